"""The commands the README, docs/ and the benchmarks' and scripts' own usage lines give are
the ones that exist: every figure there is reproduced by running them as written."""

from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

import pytest
import typer

from flakelab.cli.main import app

ROOT = Path(__file__).resolve().parent.parent
COMMAND = re.compile(r"(flakelab|python (benchmarks|scripts)/\S+\.py)( |$)")
PLACEHOLDER = "…"  # 'flakelab … --json': any command
DOCUMENTS = [ROOT / "README.md", *sorted(ROOT.glob("docs/*.md"))]


def documented_commands() -> list[tuple[str, str]]:
    """(where, command) for every command in backticks or a code block of the README and
    docs/ (each of a line's commands joined by &&), and every usage line of a benchmark's or
    a script's docstring."""
    found = []
    for path in DOCUMENTS:
        text = path.read_text()
        spans = re.findall(r"`([^`\n]+)`", text)
        lines = [ln.strip() for block in re.findall(r"```\w*\n(.*?)```", text, re.S)
                 for ln in block.splitlines()]  # fmt: skip
        parts = [part.strip() for c in spans + lines for part in c.split(" && ")]
        found += [(path.name, c) for c in parts if COMMAND.match(c)]
    for path in sorted([*ROOT.glob("benchmarks/*.py"), *ROOT.glob("scripts/*.py")]):
        found += [(path.name, ln.strip()) for ln in path.read_text().splitlines()
                  if COMMAND.match(ln.strip())]  # fmt: skip
    return found


@functools.cache
def flakelab_command():
    """The CLI's commands as click builds them (once: typer builds every one on each call)."""
    return typer.main.get_command(app)


def cli_options(words: list[str]) -> tuple[set[str], list[str]]:
    """The options of the flakelab command ``words`` names, and the words after its name."""
    command = flakelab_command()
    while hasattr(command, "commands") and words and not words[0].startswith("-"):
        sub = command.get_command(None, words[0])
        if sub is None:
            raise LookupError(f"no command {words[0]!r} in {command.name}")
        command, words = sub, words[1:]
    names = {name for p in command.params for name in (*p.opts, *p.secondary_opts)}
    return names | {"--help"}, words


def script_options(path: Path) -> set[str]:
    """The options a benchmark or script declares (``add_argument``), in itself and in the
    local modules it imports (``_matcher``'s shared harness options)."""
    modules = re.findall(r"^(?:from|import) (_?\w+)", path.read_text(), re.M)
    files = [
        path,
        *(path.parent / f"{m}.py" for m in modules if (path.parent / f"{m}.py").exists()),
    ]
    names = {"-h", "--help"}
    for file in files:
        for node in ast.walk(ast.parse(file.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "add_argument":
                names |= {a.value for a in node.args if isinstance(a, ast.Constant)}
    return names


def unknown_options(command: str) -> list[str]:
    words = re.sub(r"[\[\]|]", " ", command).split()
    if words[0] == "flakelab":
        known, rest = cli_options(words[1:])
    else:
        path = ROOT / words[1]
        if not path.exists():
            return [f"no script {words[1]}"]
        known, rest = script_options(path), words[2:]
    used = {w.split("=")[0].rstrip(",.;:)") for w in rest if re.match(r"--?[a-zA-Z]", w)}
    return sorted(used - known)


def test_the_documents_give_commands_at_all():
    """The extraction finds what it checks: the Quickstart's command among hundreds."""
    commands = documented_commands()
    assert len(commands) > 200
    assert ("README.md", "flakelab match --example") in commands


def test_every_documented_command_and_option_exists():
    wrong = []
    for where, command in documented_commands():
        if command.split()[1:2] == [PLACEHOLDER]:
            continue
        try:
            unknown = unknown_options(command)
        except LookupError as error:
            unknown = [str(error)]
        wrong += [f"{where}: {command}: {u}" for u in unknown]
    assert not wrong, "\n".join(wrong)


def test_a_misspelt_option_or_command_is_caught():
    assert unknown_options("flakelab match --example --jsn") == ["--jsn"]
    assert unknown_options("python benchmarks/aim_off.py --habits H --targts 3") == ["--targts"]
    assert unknown_options("python benchmarks/aim_off.py --world-habits 1,1,0") == []
    with pytest.raises(LookupError, match="'evaluat'"):
        unknown_options("flakelab model evaluat F")


LINK = re.compile(r"\]\(([^)\s]+)\)")


def heading_anchor(heading: str) -> str:
    """The anchor GitHub gives a Markdown heading: lower case, punctuation dropped, each space
    a hyphen (so "A, b" gives "a-b" and "x + y" gives "x--y")."""
    kept = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return kept.replace(" ", "-")


def prose(path: Path) -> str:
    """The text of the Markdown file ``path`` without its code blocks."""
    return re.sub(r"```.*?```", "", path.read_text(), flags=re.S)


def is_external(target: str) -> bool:
    """Whether a link leads off these documents (https: and the like: not ours to check)."""
    return re.match(r"[a-z]+:", target) is not None


def document_anchors(path: Path) -> set[str]:
    return {heading_anchor(h) for h in re.findall(r"^#{1,6} (.+)$", prose(path), re.M)}


def broken_links(path: Path) -> list[str]:
    """The links of ``path`` to a file or a heading of these documents that is not there."""
    broken = []
    for target in LINK.findall(prose(path)):
        if is_external(target):
            continue
        file, _, anchor = target.partition("#")
        linked = (path.parent / file).resolve() if file else path
        if not linked.exists():
            broken.append(f"{path.name}: {target}: no such file")
        elif anchor and linked.suffix == ".md" and anchor not in document_anchors(linked):
            broken.append(f"{path.name}: {target}: no such heading")
    return broken


def test_heading_anchors_are_githubs():
    assert heading_anchor("The main job: `flakelab match`") == "the-main-job-flakelab-match"
    assert heading_anchor("Match harness, 200 targets + 50 with a new toner") == (
        "match-harness-200-targets--50-with-a-new-toner"
    )


def test_every_link_between_the_documents_leads_somewhere():
    """The README and the pages under docs/ link to each other's files, headings and images:
    each link's file and heading exist (the README was split into docs/ at stop 111)."""
    links = [t for path in DOCUMENTS for t in LINK.findall(prose(path))]
    assert sum(not is_external(t) for t in links) > 30
    broken = [b for path in DOCUMENTS for b in broken_links(path)]
    assert not broken, "\n".join(broken)


def test_a_broken_link_is_caught(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# Page\n\n[there](page.md#page) [gone](gone.md) [lost](page.md#lost)\n")
    assert broken_links(page) == [
        "page.md: gone.md: no such file",
        "page.md: page.md#lost: no such heading",
    ]


def test_the_readme_leads_to_every_page_under_docs():
    """A newcomer starts at the README: each page under docs/ is linked from it."""
    linked = {
        (ROOT / t.partition("#")[0]).resolve() for t in LINK.findall(DOCUMENTS[0].read_text())
    }
    pages = {p.resolve() for p in DOCUMENTS[1:]}
    assert len(pages) >= 9
    assert not pages - linked, sorted(p.name for p in pages - linked)
