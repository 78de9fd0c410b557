#!/usr/bin/env bash
# Run configs/paper1-full-length.yaml in phases so that a partial run is still useful (issue 39):
#   1. the four cheap scenarios, 3 seeds: proposed pipeline, competitors (paper's and tuned
#      settings, tuned s4pcs excepted), the deviation ledger's switches;
#   2. the cheap scenarios, 2 seeds: Table 3/5 ablations of the paper's top descriptors (HoD-S,
#      SHOT; the other four follow in the last phases);
#   3. seeds 4 and 5 of the proposed pipeline and the competitors with the paper's settings;
#   4. sim-eoi (3 100-point scans), HoD-S rows and the competitors, then everything.
# The store is resumable: rerunning skips finished jobs; the committed store
# (docs/results/paper1-full-length/store/) seeds a new OUT. Copy OUT/results.sqlite back there
# after a part. Usage:
#   nice -n 10 bash benchmarks/paper1/paper1_full_length.sh [OUT]   (default bench/paper1-full-length)
set -u
OUT=${1:-bench/paper1-full-length}
GRID=configs/paper1-full-length.yaml
# the store of the parts run so far is committed: a fresh clone resumes from it
STORE=docs/results/paper1-full-length/store/results.sqlite
if [ ! -e "$OUT/results.sqlite" ] && [ -e "$STORE" ]; then
  mkdir -p "$OUT" && cp "$STORE" "$OUT/results.sqlite"
fi
CHEAP=(--scenario sim-bennu --scenario sim-voyager --scenario sim-orion --scenario sim-helical)
PROPOSED=(-m 'feature:*+gcc+hinf' -m 'feature:*+gcc+kalman' -m 'feature:*+gcc+alphabeta'
          -m 'feature:*+gcc+sdre')
CORE=("${PROPOSED[@]}" -m 'paper1-*' -m 'icp-*' -m 'sicp-*' -m 'ledger:*')
run() { echo "== $(date -u +%H:%M:%S) relnav benchmark $GRID $*"; relnav benchmark "$GRID" --out "$OUT" --no-report "$@"; }
run "${CHEAP[@]}" --seeds 3 "${CORE[@]}"
run "${CHEAP[@]}" --seeds 2 -m 'feature:hods+gcc+icp' -m 'feature:shot+gcc+icp' \
    -m 'feature:hods+ransac+alphabeta' -m 'feature:shot+ransac+alphabeta'
run "${CHEAP[@]}" "${PROPOSED[@]}" -m 'paper1-*'
run --scenario sim-eoi --seeds 3 -m 'feature:hods+gcc+*' -m 'paper1-*' -m 'icp-*' -m 'ledger:own-radius'
run "${CHEAP[@]}"
run
echo "== $(date -u +%H:%M:%S) done"
