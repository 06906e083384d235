#!/usr/bin/env bash
# One device session's checks, as one command (the device tool's `run`), writing under $OUT:
# benchmarks/accelerator.py (ACC seconds at most, default 330; ACC=0 skips it), then the test suite
# on the accelerator for the time left of TOTAL seconds (default 585), 14 workers, its log in
# $OUT/tests.log (`-v`: every test's outcome, so a run cut by the limit still tells which passed).
# Missing packages (ezdxf is not in the device image) travel as wheels in .whl/ (carry ".whl"):
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#     --platform manylinux2014_x86_64 -d .whl ezdxf==1.4.5
# Extra pytest arguments in TESTS (e.g. the files a previous session did not reach).
# Measured 2026-11-26 on an H200: the full accelerator.py takes > 420 s (its 2e6-design Monte
# Carlo at chunk 100000 did not finish), the suite about 300 s at -n 14.
T0=$(date +%s)
export PYTHONUNBUFFERED=1
if ls .whl/*.whl >/dev/null 2>&1; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 3
  export PYTHONPATH=/tmp/site:$PWD
else
  export PYTHONPATH=$PWD
fi
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv
python3 -c "import jax, pytest; print('jax', jax.__version__, jax.devices(), 'pytest', pytest.__version__)"
ACC=${ACC:-330}
if [ "$ACC" != 0 ]; then
  timeout -s INT -k 15 "$ACC" python3 benchmarks/accelerator.py --json "$OUT/accelerator.json" ${ACC_ARGS:-} 2>&1 \
    | tee "$OUT/accelerator.log"
fi
LEFT=$(( ${TOTAL:-585} - ($(date +%s) - T0) ))
echo "tests get $LEFT s"
if [ "$LEFT" -gt 30 ]; then
  # shellcheck disable=SC2086
  XLA_PYTHON_CLIENT_PREALLOCATE=false timeout -s INT -k 20 "$LEFT" python3 -m pytest -n "${NW:-14}" -v -rfE \
    --tb=short -p no:cacheprovider ${TESTS:-} 2>&1 | tee "$OUT/tests.log" | grep -v " PASSED "
fi
echo "done after $(( $(date +%s) - T0 )) s"
