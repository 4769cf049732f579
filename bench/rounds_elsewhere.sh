#!/usr/bin/env bash
# The bench's paired thread scaling, several rounds back to back, on a machine where the package is
# not installed (e.g. a lent machine with numpy, scipy and numba but no network): run from the
# repository root, with scikit-fem's and meshio's wheels in $WHEELS. Each round's JSON and the
# printout go to $OUT, a JSON per round, so that a run cut short keeps its finished rounds (where a run
# is not cut short, `skdgmpm bench --repeat N` does the same in one call). docs/bench/session23.md
# was measured so.
#
#   WHEELS=.whl OUT=/tmp/out METHODS=dgmpm-ctu,ader-dgfem-1 THREADS=1,2 ROUNDS=3 bash bench/rounds_elsewhere.sh
set -u
R=$(pwd)
SITE=$(mktemp -d)
OUT=${OUT:-$R/rounds}
mkdir -p "$OUT"
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target "$SITE" "${WHEELS:-.whl}"/*.whl || exit 1
cp -r skdgmpm "$SITE/skdgmpm" && for d in forms materials cases; do cp -r $d "$SITE/skdgmpm/$d"; done  # pyproject's package-dir
export PYTHONPATH=$SITE XDG_CACHE_HOME=${XDG_CACHE_HOME:-$SITE/cache} PYTHONUNBUFFERED=1 MPLBACKEND=Agg
cd "$SITE"      # the installed copy, not the checkout's skdgmpm/, is imported
# the bench spawns its rows: the entry point must be an importable file guarded by __main__
printf 'import sys\nfrom skdgmpm.cli import main\nif __name__ == "__main__":\n    sys.exit(main())\n' > skd.py
python3 -c "import numba, numpy, sys, os; print('numba', numba.__version__, 'numpy', numpy.__version__, 'python', sys.version.split()[0], 'cpus', len(os.sched_getaffinity(0)))" | tee -a "$OUT/rounds.log"
N=${SIZES:-256}
for r in $(seq 1 "${ROUNDS:-3}"); do
  S=$(date +%s)
  python3 skd.py bench --methods "${METHODS:-dgmpm-ctu,dgmpm-dcu,ader-dgfem-1}" --sizes "$N" --steps 9 \
      --threads "${THREADS:-1,2}" --quiet --json "$OUT/round${r}_$N.json" 2>&1 | tee -a "$OUT/rounds.log"
  echo "round $r: $(( $(date +%s) - S )) s (the first round compiles); load $(cat /proc/loadavg)" | tee -a "$OUT/rounds.log"
done
