#!/usr/bin/env bash
# One device session's synthesis check, as one command (the device tool's `run`), writing under $OUT:
# the 26 LINK-ABC letters (ONLY: fewer) (synthesis_letters.py, LIMIT seconds a letter, default 60) in PROCS
# processes side by side on the one device (default 5: a letter group each, so 26 letters take
# about 6 × LIMIT s), merged into $OUT/letters.json, the logs (each round) in $OUT/letters.log;
# then, for the time left of TOTAL seconds (default 570), the tests in TESTS (default: synthesis,
# stored programs, cache differential, distributed) on the device, log in $OUT/tests.log.
# The letters have no licence and never enter the repository: copy alphabet.npy and alpha_res.npy
# into an ignored folder that travels, e.g. .whl/linkabc/ (carry ".whl"), or set LINKABC.
# Missing packages travel as wheels in .whl/ (see device_run.sh).
# XLA_PYTHON_CLIENT_PREALLOCATE=false: the processes share the device's memory.
T0=$(date +%s)
export PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false
if ls .whl/*.whl >/dev/null 2>&1; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 3
  export PYTHONPATH=/tmp/site:$PWD
else
  export PYTHONPATH=$PWD
fi
LINKABC=${LINKABC:-.whl/linkabc/alphabet.npy}
LIMIT=${LIMIT:-60}
GROUPS_N=${PROCS:-5}
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader 2>&1 | tee "$OUT/letters.log"
python3 -c "import jax; print('jax', jax.__version__, jax.devices())" 2>&1 | tee -a "$OUT/letters.log"
ALL=${ONLY:-ABCDEFGHIJKLMNOPQRSTUVWXYZ}
TMP=$(mktemp -d)
pids=()
for ((g = 0; g < GROUPS_N; g++)); do
  only=""
  for ((i = g; i < ${#ALL}; i += GROUPS_N)); do only+=${ALL:i:1}; done
  timeout -s INT -k 15 "${LETTERS_TIMEOUT:-420}" python3 benchmarks/synthesis_letters.py --letters "$LINKABC" \
    --only "$only" --time-limit "$LIMIT" --log --out "$TMP/g$g.json" >"$TMP/g$g.log" 2>&1 &
  pids+=($!)
done
# the device's load while they run
(nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv,noheader -l 10 >"$TMP/smi.log" 2>&1 &) 
wait "${pids[@]}"
pkill -f "nvidia-smi --query-gpu=utilization" 2>/dev/null
for ((g = 0; g < GROUPS_N; g++)); do echo "== group $g"; cat "$TMP/g$g.log"; done >>"$OUT/letters.log"
echo "== nvidia-smi every 10 s (utilization, memory)" >>"$OUT/letters.log"; cat "$TMP/smi.log" >>"$OUT/letters.log"
python3 benchmarks/synthesis_letters.py --merge "$TMP"/g*.json --out "$OUT/letters.json" 2>&1 | tee -a "$OUT/letters.log"
echo "letters done after $(( $(date +%s) - T0 )) s" | tee -a "$OUT/letters.log"
LEFT=$(( ${TOTAL:-570} - ($(date +%s) - T0) ))
echo "tests get $LEFT s"
if [ "$LEFT" -gt 30 ]; then
  # shellcheck disable=SC2086
  timeout -s INT -k 15 "$LEFT" python3 -m pytest -n "${NW:-8}" -v -rfE --tb=short -p no:cacheprovider \
    ${TESTS:-tests/test_synthesis.py tests/test_synthesis_memo.py tests/test_synthesis_spread.py tests/test_cache_differential.py tests/test_distributed.py} \
    2>&1 | tee "$OUT/tests.log" | grep -v " PASSED "
fi
echo "done after $(( $(date +%s) - T0 )) s"
