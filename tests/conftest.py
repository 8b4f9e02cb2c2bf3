"""Shared fixtures: the real reference data in ../shared/data (skipped when absent) and a
live PostgreSQL for the database tests (skipped when none can be had)."""

from __future__ import annotations

import functools
import multiprocessing
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
import uuid
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest

from flakelab.core import Geometry, Measurement
from flakelab.core.spectra import WAVELENGTHS

os.environ.pop("COLUMNS", None)  # the CLI's tables at their piped width, whatever a shell exports
os.environ.pop("FLAKELAB_SHOP", None)  # no workplace's shop but the one a test sets

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
MA_T12 = SHARED / "ma-t12"
PIGMENT_KM = SHARED / "pigment-km"
REFERENCE_BRDF = SHARED / "reference-brdf"


@pytest.fixture(scope="session", autouse=True)
def _cli_built_once():
    """The CLI's commands built from flakelab's functions once for the session: typer's test
    runner builds them again on every call (0.05-0.1 s of reading type hints, over hundreds
    of calls). Where typer's runner no longer builds them by this name, nothing changes."""
    import typer.testing

    built = getattr(typer.testing, "_get_command", None)
    if built is None:
        yield
        return
    typer.testing._get_command = functools.cache(built)
    yield
    typer.testing._get_command = built


def _run_cli(
    *args: object, env: dict[str, str] | None = None, input: bytes | None = None
) -> subprocess.CompletedProcess:
    """The CLI run in this process, as a finished process (exit status, stdout, stderr), with
    ``env`` added to the environment while it runs and ``input`` piped into its standard
    input: a new interpreter would cost each call 3-4 s
    of imports. An exception that escapes the command (a bug, which a user would meet as a
    traceback) is raised here, so that the test fails on it."""
    from typer.testing import CliRunner

    from flakelab.cli.main import app

    result = CliRunner().invoke(app, [str(a) for a in args], env=env, input=input)
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    return subprocess.CompletedProcess(args, result.exit_code, result.stdout, result.stderr)


@pytest.fixture(scope="session")
def workplaces() -> multiprocessing.context.BaseContext:
    """Processes that stand for workplaces acting at once, forked from one server that
    imported torch, flakelab and the tests' worker functions once for the session. Spawned,
    each imported them again: 4-5 s a process on two cores, most of these tests' time. The
    server runs no torch before it forks, so the fork is safe where forking a process whose
    OpenMP threads ran may hang (why ``match --all`` itself spawns)."""
    server = multiprocessing.get_context("forkserver")
    server.set_forkserver_preload(["torch", "flakelab.models.registry", *_WORKER_MODULES])
    return server


_WORKER_MODULES = ("test_cases", "test_lots")  # the modules whose functions the pools run


def _interrupting(original, call: int, after: bool = False):
    """``original``, raising KeyboardInterrupt (a Ctrl-C) at its ``call``-th call: before it
    runs, or once it has run (``after``)."""
    calls = []

    def wrapper(*args, **kwargs):
        calls.append(1)
        if len(calls) == call and not after:
            raise KeyboardInterrupt
        result = original(*args, **kwargs)
        if len(calls) == call:
            raise KeyboardInterrupt
        return result

    return wrapper


@pytest.fixture
def ctrl_c():
    """A function wrapped to be interrupted at its n-th call (:func:`_interrupting`)."""
    return _interrupting


@pytest.fixture(scope="session", autouse=True)
def user_data_folder(tmp_path_factory) -> Path:
    """A user data folder of the test session's own: the commands that name no database use
    the one there, and the current model is the one promoted there (else the shipped one), so
    the tests neither read nor write the user's own."""
    folder = tmp_path_factory.mktemp("user-data")
    before = os.environ.get("XDG_DATA_HOME")
    os.environ["XDG_DATA_HOME"] = str(folder)
    yield folder
    if before is None:
        del os.environ["XDG_DATA_HOME"]
    else:
        os.environ["XDG_DATA_HOME"] = before


@pytest.fixture(scope="session")
def cli():
    """Run the CLI in this process (:func:`_run_cli`)."""
    return _run_cli


def _pigment_km_rows(name: str, first_nm: int, spectra: int = 1) -> dict[str, np.ndarray]:
    """Rows ``name → values`` of a file of ../shared/data/pigment-km (tab-separated, first
    band at ``first_nm``, 10 nm apart), each of its ``spectra`` (Okumura's rows: K, then S)
    cut to flakelab's 400–700 nm grid, one after the other."""
    rows = {}
    for line in (PIGMENT_KM / name).read_text().splitlines():
        if not line.strip():
            continue
        label, *fields = [f for f in line.split("\t") if f.strip()]
        values = np.array(fields, dtype=float).reshape(spectra, -1)
        start = (int(WAVELENGTHS[0]) - first_nm) // 10
        rows[label.strip().strip('"')] = values[:, start : start + WAVELENGTHS.size].ravel()
    return rows


@pytest.fixture(scope="session")
def pigment_km():
    """The reader of ../shared/data/pigment-km's files (:func:`_pigment_km_rows`)."""
    if not PIGMENT_KM.is_dir():
        pytest.skip(f"reference data not found at {PIGMENT_KM} (../shared/data is absent)")
    return _pigment_km_rows


@pytest.fixture(scope="session")
def ma_t12_dir() -> Path:
    if not MA_T12.is_dir():
        pytest.skip(f"reference data not found at {MA_T12} (../shared/data is absent)")
    return MA_T12


def _reference_brdf(fit: str) -> Path:
    from flakelab.physics.reference_brdf import REFERENCE_FITS

    path = REFERENCE_BRDF / REFERENCE_FITS[fit][0]
    if not path.is_file():
        pytest.skip(f"reference data not found at {path} (../shared/data is absent)")
    return path


@pytest.fixture(scope="session")
def gunther_fits_file() -> Path:
    """Günther et al.'s Cook-Torrance fits of eight measured car paints (reference-brdf)."""
    return _reference_brdf("gunther")


@pytest.fixture(scope="session")
def merl_abc_fits_file() -> Path:
    """Löw et al.'s ABC fits of the 100 MERL BRDFs, 25 of them paints (reference-brdf)."""
    return _reference_brdf("merl_abc")


@pytest.fixture(scope="session")
def merl_sgd_fits_file() -> Path:
    """Bagher et al.'s SGD fits of the same 100 MERL BRDFs (reference-brdf)."""
    return _reference_brdf("merl_sgd")


@pytest.fixture(scope="session")
def ma_t12_files(ma_t12_dir: Path) -> list[Path]:
    files = sorted(ma_t12_dir.glob("*.xlsx"))
    assert files, f"no MA-T12 exports in {ma_t12_dir}"
    return files


@pytest.fixture
def rich_measurement() -> Measurement:
    """A synthetic measurement using every field, including an out-of-plane geometry."""
    rng = np.random.default_rng(7)
    geometries = tuple(Geometry.parse(n) for n in ("45as15", "45as45", "45as110", "45as25az90"))
    return Measurement(
        sample='rich; sample, with "quotes"',
        geometries=geometries,
        wavelengths=WAVELENGTHS,
        # up to 1.8 near specular; 45as110, far from it, no brighter than a white
        reflectance=rng.uniform(0.01, 1.8, (4, 31)) * np.array([[1.0], [1.0], [0.5], [1.0]]),
        texture={"Sa15": 12.5, "Si15": 9.25, "SG": 7.0, "G": 4.125},
        instrument="BYK-mac i",
        measured_at=datetime(2026, 3, 4, 5, 6, 7),
        # its 45as110 darker: a colour its recovered spectra give no brighter than a white
        stored_lab=rng.uniform([10, -40, -40], [100, 40, 40], (4, 3)) * [[1], [1], [0.5], [1]],
        metadata={"shop": "north"},
    )


@pytest.fixture(scope="session")
def postgres_server():
    """A live PostgreSQL server's URL without a database name: FLAKELAB_TEST_POSTGRES_URL,
    else a throwaway cluster started with this machine's initdb and pg_ctl (as the postgres
    user when the tests run as root); skipped when neither is at hand."""
    if url := os.environ.get("FLAKELAB_TEST_POSTGRES_URL"):
        yield url.rstrip("/")
        return
    pytest.importorskip("psycopg", reason="PostgreSQL's driver: pip install 'flakelab[postgres]'")
    initdb, pg_ctl = shutil.which("initdb"), shutil.which("pg_ctl")
    if not (initdb and pg_ctl):
        pytest.skip("no PostgreSQL here: neither FLAKELAB_TEST_POSTGRES_URL nor initdb/pg_ctl")
    folder = Path(tempfile.mkdtemp(prefix="flakelab-postgres-"))  # /tmp: any user reaches it
    as_user: list[str] = []
    if os.geteuid() == 0:  # the server refuses to run as root
        try:
            owner = pwd.getpwnam("postgres")
        except KeyError:
            shutil.rmtree(folder, ignore_errors=True)
            pytest.skip("running as root, and no postgres user to run PostgreSQL as")
        os.chown(folder, owner.pw_uid, owner.pw_gid)
        as_user = ["runuser", "-u", "postgres", "--"]
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    data = folder / "data"
    options = f"-p {port} -k {folder} -c listen_addresses=127.0.0.1 -c fsync=off"
    try:
        for command in (
            [initdb, "-D", str(data), "--auth=trust", "-U", "flakelab", "--no-sync"],
            [pg_ctl, "-D", str(data), "-o", options, "-l", str(folder / "log"), "-w", "start"],
        ):
            subprocess.run(as_user + command, check=True, capture_output=True, timeout=120)
    except (subprocess.SubprocessError, OSError) as error:
        shutil.rmtree(folder, ignore_errors=True)
        pytest.skip(f"could not start a PostgreSQL server here: {error}")
    try:
        yield f"postgresql+psycopg://flakelab@127.0.0.1:{port}"
    finally:
        stop = [pg_ctl, "-D", str(data), "-m", "immediate", "stop"]
        subprocess.run(as_user + stop, capture_output=True, timeout=120)
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(params=["sqlite", "postgresql"])
def database_url(request, tmp_path):
    """A new, empty database's URL: a SQLite file, and a database of its own on a live
    PostgreSQL (dropped afterwards)."""
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'cases.db'}"
        return
    import psycopg

    server = request.getfixturevalue("postgres_server")
    name = f"flakelab_test_{uuid.uuid4().hex[:12]}"
    admin = server.replace("postgresql+psycopg://", "postgresql://") + "/postgres"
    with psycopg.connect(admin, autocommit=True) as connection:
        connection.execute(f"CREATE DATABASE {name}")
    yield f"{server}/{name}"
    with psycopg.connect(admin, autocommit=True) as connection:
        connection.execute(f"DROP DATABASE {name} WITH (FORCE)")  # the test's engines still hold it
