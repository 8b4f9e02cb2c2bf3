#!/usr/bin/env bash
# The test suite under another CPU's arithmetic: tests that pin where an optimiser ends can
# pass on one machine and fail on the next, because vector width, the BLAS kernel and the
# thread count change the order of floating-point sums (stop 61 lost two tests that way).
# Each variant runs the whole suite with the kernels such a machine would use:
#
#   avx2      an AVX2 machine without AVX-512 (torch, MKL, OpenBLAS and numpy kernels)
#   baseline  torch's portable kernels, MKL's SSE4.2 path, one thread
#
#   bash scripts/other_cpus_check.sh [avx2] [baseline] [-- PYTEST ARGS]
#
# Run from an environment where `pip install -e '.[test]'` has been done. Exits non-zero
# when any variant fails; each variant's output goes to ${OUT:-other-cpus}/VARIANT.txt.
set -uo pipefail
cd "$(dirname "$0")/.."
OUT="${OUT:-other-cpus}"
mkdir -p "$OUT"

variants=()
while [[ $# -gt 0 && "$1" != "--" ]]; do variants+=("$1"); shift; done
[[ "${1:-}" == "--" ]] && shift
[[ ${#variants[@]} -eq 0 ]] && variants=(avx2 baseline)

# the environment that selects each variant's kernels
declare -A settings=(
    [avx2]='ATEN_CPU_CAPABILITY=avx2 MKL_ENABLE_INSTRUCTIONS=AVX2 OPENBLAS_CORETYPE=Haswell
            NPY_DISABLE_CPU_FEATURES=X86_V4,AVX512_ICL,AVX512_SPR'
    [baseline]='ATEN_CPU_CAPABILITY=default MKL_ENABLE_INSTRUCTIONS=SSE4_2 MKL_CBWR=COMPATIBLE
                OPENBLAS_CORETYPE=Nehalem NPY_DISABLE_CPU_FEATURES=X86_V3,X86_V4,AVX512_ICL,AVX512_SPR
                OMP_NUM_THREADS=1'
)
for variant in "${variants[@]}"; do
    if [[ -z "${settings[$variant]:-}" ]]; then
        echo "unknown variant '$variant' (known: ${!settings[*]})" >&2
        exit 2
    fi
done

failed=0
for variant in "${variants[@]}"; do
    # shellcheck disable=SC2086  # the settings split into NAME=VALUE words on purpose
    env ${settings[$variant]} python -m pytest -q -p no:cacheprovider "$@" \
        > "$OUT/$variant.txt" 2>&1
    rc=$?
    echo "$variant: rc $rc, $(tail -n 1 "$OUT/$variant.txt")"
    [[ $rc -ne 0 ]] && failed=1
done
exit $failed
