#!/usr/bin/env bash
# A fuzzing campaign (not in CI): every target, or the ones named, run to a count of executions
# at the campaign settings of docs/fuzzing.md (inputs up to 4 kB, ASan without its fake stack,
# nice 19), one after the other, each continuing from its corpus. Prints one Markdown row per
# target for docs/fuzzing.md's table: executions, exec/s, coverage (the edges libFuzzer saw
# covered over the target's instrumented ones) and findings (0, or where the input is).
#
#   scripts/fuzz_campaign.sh [TARGET...]          run, then print the rows
#   scripts/fuzz_campaign.sh --report [TARGET...] only print the rows of the last runs' logs
#
# Environment: FUZZ_RUNS (executions per target; default 10000000), and everything
# scripts/fuzz.sh reads. About 10-60 minutes per target on one core (docs/fuzzing.md).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
report_only=0
if [ "${1:-}" = "--report" ]; then
  report_only=1
  shift
fi
source scripts/fuzz_targets.sh
targets=("${@:-${fuzz_targets[@]}}")
artifacts=build/fuzz/artifacts

failed=()
if [ "$report_only" = 0 ]; then
  for t in "${targets[@]}"; do
    # A timeout is wall time: at nice 19 beside a build the fuzzer can wait seconds for a core
    # (fuzz_pcd "timed out" at 14 s on an input that runs in 0.23 s alone), so campaigns allow
    # 60 s; CI's short runs keep 10.
    FUZZ_MAX_LEN=4096 FUZZ_RUNS="${FUZZ_RUNS:-10000000}" FUZZ_TIMEOUT="${FUZZ_TIMEOUT:-60}" \
      FUZZ_ASAN_OPTIONS=detect_stack_use_after_return=0 \
      nice -n 19 bash scripts/fuzz.sh 0 "$t" || failed+=("$t")
  done
fi

# One row from a target's last log (scripts/fuzz.sh writes it): libFuzzer's final statistics,
# the "cov:" of its last status line and the counters of the instrumented module.
echo "| target | executions | exec/s | coverage (edges) | findings |"
echo "| --- | ---: | ---: | ---: | --- |"
for t in "${targets[@]}"; do
  log="$artifacts/$t/last_run.log"
  if [ ! -f "$log" ]; then
    echo "| \`$t\` | no log | | | |"
    continue
  fi
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
  cov=$(grep -oE 'cov: [0-9]+' "$log" | tail -1 | grep -oE '[0-9]+' || true)
  counters=$(grep -oE '[0-9]+ inline 8-bit counters' "$log" | head -1 | grep -oE '^[0-9]+' || true)
  pct=""
  [ -n "$cov" ] && [ -n "$counters" ] && pct=$(awk -v c="$cov" -v n="$counters" 'BEGIN{printf " (%.1f %%)", 100*c/n}')
  findings=0
  grep -qE 'ERROR: |Test unit written|deadly signal' "$log" && findings="see $artifacts/$t/"
  printf '| `%s` | %s | %s | %s / %s%s | %s |\n' "$t" "${runs:-?}" "${rate:-?}" "${cov:-?}" \
    "${counters:-?}" "$pct" "$findings"
done
if [ ${#failed[@]} -ne 0 ]; then
  echo "fuzz_campaign.sh: ${#failed[@]} target(s) failed: ${failed[*]}" >&2
  exit 1
fi
