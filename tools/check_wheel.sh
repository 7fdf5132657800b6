#!/usr/bin/env bash
# The package as a user gets it (CI runs this after the tests; ./run.sh wheel runs it by hand):
#  1. build the wheel from the repository's tracked files (a copy: a build/ or *.egg-info left by
#     an earlier build would add stale files);
#  2. check that it carries every tracked file of hyde_bsdf/: the code, the data tables
#     (hyde_bsdf/data/*.npz), the scenes and the validation scripts;
#  3. install it into a fresh virtual environment (pip resolves the dependencies);
#  4. from a folder outside the checkout, with no PYTHONPATH: `hyde-bsdf demo` (a small picture),
#     and with --validate also `hyde-bsdf validate --quick` (minutes: not in CI).
# Usage: tools/check_wheel.sh [--validate] [--keep]   (PYTHON: the interpreter that builds the
# wheel and makes the fresh environment, default .venv/bin/python; --keep leaves the work folder)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
py=${PYTHON:-$root/.venv/bin/python}
validate=0; keep=0
for arg in "$@"; do
    case "$arg" in
        --validate) validate=1 ;;
        --keep) keep=1 ;;
        *) echo "usage: tools/check_wheel.sh [--validate] [--keep]" >&2; exit 2 ;;
    esac
done
work=$(mktemp -d "${TMPDIR:-/tmp}/hyde-wheel.XXXXXX")
if [ "$keep" = 1 ]; then echo "[wheel] work folder: $work" >&2; else trap 'rm -rf "$work"' EXIT; fi
step() { echo "[wheel] $1 ($(( SECONDS - t0 )) s)" >&2; }
t0=$SECONDS

mkdir "$work/src" "$work/run"
git -C "$root" ls-files -z pyproject.toml README.md hyde_bsdf | (cd "$root" && xargs -0 cp --parents -t "$work/src")
"$py" -m pip wheel -q --no-deps -w "$work/dist" "$work/src" >&2
wheel=$(ls "$work"/dist/hyde_bsdf-*.whl)
step "built $(basename "$wheel")"

(cd "$root" && git ls-files hyde_bsdf) | "$py" -c '
import sys, zipfile
names = set(zipfile.ZipFile(sys.argv[1]).namelist())
missing = [f for f in sys.stdin.read().split("\n") if f and f not in names]
if missing:
    sys.exit(f"[wheel] the wheel lacks {len(missing)} file(s) of hyde_bsdf/: " + ", ".join(missing[:10]))
data = sum(n.startswith("hyde_bsdf/data/") for n in names)
print(f"[wheel] it carries every tracked file of hyde_bsdf/ ({data} data files)", file=sys.stderr)' "$wheel"

"$py" -m venv "$work/venv"
"$work/venv/bin/python" -m pip install -q --no-compile "$wheel" >&2   # no .pyc of every dependency: a third of the time
step "installed into a fresh virtual environment"

cd "$work/run"
unset PYTHONPATH
"$work/venv/bin/hyde-bsdf" demo -o demo --width 64 --height 40 --spp 4 -q
for f in demo.exr demo_rgb.png demo_dolp.png demo_overview.png; do
    [ -s "demo/$f" ] || { echo "[wheel] hyde-bsdf demo wrote no demo/$f" >&2; exit 1; }
done
step "hyde-bsdf demo from $(pwd): wrote demo/demo.exr and its pictures"

if [ "$validate" = 1 ]; then
    "$work/venv/bin/hyde-bsdf" validate --quick -o report
    step "hyde-bsdf validate --quick from $(pwd): report/index.html"
fi
