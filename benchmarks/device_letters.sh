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
# XLA_PYTHON_CLIENT_PREALLOCATE=false: the processes share the device's memory. TOTAL=0: no tests.
# MAXLINKS=10: the ten-bars too (default 8).
# The GPU goal's measurement in a session's 15 minutes (2026-11-27, H100, b1e4d30): all 26 letters
# with MAXLINKS=10 PROCS=5 WARM=1 LIMIT=57 TOTAL=0 LETTERS_TIMEOUT=390 (the device tool's kind
# nvidia-h100-x1, carry .whl, timeout 480) took 399 s of command (warm-up 47 s; every letter 56.3-57.2 s;
# mean 0.0226, median 0.0137, better than LInK on 19), about 443 s of device time with the start;
# the whole test suite after it (pytest -n 14, cut at 380 s) took the remaining 400 s.
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
# WARM=1: first compile the search's programs once (an open and a closed letter, one round each,
# at the letters' compile level), so that the processes load them from the cache instead of each
# compiling them in its first letter's time
if [ "${WARM:-0}" != 0 ]; then
  python3 - "$LINKABC" "$LIMIT" "${MAXLINKS:-8}" <<'PY' 2>&1 | tee -a "$OUT/letters.log"
import sys, time
import numpy as np, jax
jax.config.update("jax_enable_x64", True)
import jaxlink as jl
jl.enable_compilation_cache()
letters, limit = np.load(sys.argv[1]), float(sys.argv[2])
t0 = time.perf_counter()
for ch in "CO":  # C open, O closed
    jl.synthesize(letters[ord(ch) - 65], time_limit=limit, rounds=1, max_links=int(sys.argv[3]))
print(f"warm-up (compiling the programs, one round of C and O): {time.perf_counter() - t0:.1f} s", flush=True)
PY
fi
ALL=${ONLY:-ABCDEFGHIJKLMNOPQRSTUVWXYZ}
TMP=$(mktemp -d)
pids=()
for ((g = 0; g < GROUPS_N; g++)); do
  only=""
  for ((i = g; i < ${#ALL}; i += GROUPS_N)); do only+=${ALL:i:1}; done
  timeout -s INT -k 15 "${LETTERS_TIMEOUT:-420}" python3 benchmarks/synthesis_letters.py --letters "$LINKABC" \
    --only "$only" --time-limit "$LIMIT" --max-links "${MAXLINKS:-8}" --log $([ "${WARM:-0}" != 0 ] && echo --cache) --out "$TMP/g$g.json" >"$TMP/g$g.log" 2>&1 &
  pids+=($!)
done
# the device's load while they run
(nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv,noheader -l 10 >"$TMP/smi.log" 2>&1 &)
head=$(cat "$OUT/letters.log")
collect() {  # the table and the logs so far into $OUT (a run cut by the device's time keeps them)
  { echo "$head"; for ((g = 0; g < GROUPS_N; g++)); do echo "== group $g"; cat "$TMP/g$g.log" 2>/dev/null; done
    echo "== nvidia-smi every 10 s (utilization, memory)"; cat "$TMP/smi.log"; } >"$OUT/letters.log.new"
  mv "$OUT/letters.log.new" "$OUT/letters.log"
  if ls "$TMP"/g*.json >/dev/null 2>&1; then
    python3 benchmarks/synthesis_letters.py --merge "$TMP"/g*.json --out "$OUT/letters.json.new" >"$TMP/merge.log" 2>&1 \
      && mv "$OUT/letters.json.new" "$OUT/letters.json"
  fi
}
(while sleep 20; do collect; done) &
collector=$!
wait "${pids[@]}"
kill "$collector" 2>/dev/null
pkill -f "nvidia-smi --query-gpu=utilization" 2>/dev/null
collect
cat "$TMP/merge.log" | tee -a "$OUT/letters.log"
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
