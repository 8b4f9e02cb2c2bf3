#!/usr/bin/env bash
# Training on a GPU: the GPU tests and the learning benchmark, on a machine whose Python
# already holds torch with CUDA (the figures in docs/figures.md's "training on a GPU").
#
#   bash scripts/gpu_check.sh prepare   # here, with network: wheels of what such a machine lacks
#   bash scripts/gpu_check.sh           # there, from the repository root, wheels carried along
#
# The wheels go to .devwheels/ (ignored by git). They are for
# CPython 3.12 on x86-64 Linux, as the lent GPU machines have; set PYTHON_VERSION otherwise.
# flakelab is not installed there (its torch pin would replace the machine's CUDA build):
# it runs from src/ on PYTHONPATH. Outputs go to $OUT (default: ./gpu-out).
set -euo pipefail
cd "$(dirname "$0")/.."
if [[ "${1:-}" == "prepare" ]]; then
    python -m pip download --quiet --dest .devwheels --no-deps --only-binary=:all: \
        --python-version "${PYTHON_VERSION:-3.12}" --implementation cp \
        --platform manylinux2014_x86_64 --platform manylinux_2_17_x86_64 \
        colour-science colour-cxf xsdata openpyxl et-xmlfile sqlalchemy alembic mako
    exit 0
fi
OUT="${OUT:-gpu-out}"
mkdir -p "$OUT"
python3 -m pip install --quiet --no-deps --no-index --target /tmp/flakelab-site .devwheels/*.whl
export PYTHONPATH="$PWD/src:/tmp/flakelab-site"
python3 -c "import torch; assert torch.cuda.is_available(), 'torch sees no CUDA GPU'; \
print(torch.__version__, torch.cuda.get_device_name())"
python3 -m pytest -q -p no:cacheprovider tests/test_models.py -k "gpu or device or side_by_side" -rs
python3 benchmarks/learning.py --cases 61000 --epochs 1 --members 5 --device cuda --json \
    > "$OUT/members5.json"
python3 benchmarks/learning.py --device cuda --json > "$OUT/protocol.json"
cat "$OUT/members5.json" "$OUT/protocol.json"
