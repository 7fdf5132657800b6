#!/usr/bin/env bash
# hyde-bsdf set-up and entry point.  Two commands, both self-installing:
#   ./run.sh demo   -- the main job: writes the demo pictures into out/demo/
#   ./run.sh test   -- the whole test suite, on 2 worker processes (extra arguments go to pytest)
#   ./run.sh wheel  -- the wheel built, installed into a fresh virtual environment, its demo run
#                      from outside the checkout (tools/check_wheel.sh; --validate adds the quick report)
# Each one makes .venv/ inside the repository, installs the package with its
# dependencies, and makes sure a libLLVM >= 16 is present for Dr.Jit's LLVM
# back end (Debian 12's default libLLVM-15 makes Dr.Jit 1.5 abort).
set -euo pipefail
cd "$(dirname "$0")"

ensure_llvm() {
    if ldconfig -p 2>/dev/null | grep -qE 'libLLVM(-|\.so\.)(1[6-9]|[2-9][0-9])'; then
        return 0
    fi
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "[run.sh] installing libllvm19 for Dr.Jit's LLVM back end" >&2
        apt-get update -qq >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19 >/dev/null
    else
        echo "[run.sh] no libLLVM >= 16 and cannot install it: LLVM variants will fall back to scalar ones" >&2
    fi
}

ensure_venv() {
    [ -x .venv/bin/python ] || python3 -m venv .venv
    local stamp=".venv/.installed-$(sha1sum pyproject.toml | cut -c1-12)"
    if [ ! -f "$stamp" ]; then
        echo "[run.sh] installing hyde-bsdf and its dependencies into .venv" >&2
        .venv/bin/python -m pip install -q --upgrade pip >/dev/null
        .venv/bin/python -m pip install -q -e '.[test,distributed]'
        touch "$stamp"
    fi
}

cmd="${1:-}"; shift || true
case "$cmd" in
    demo)
        ensure_llvm; ensure_venv
        exec .venv/bin/hyde-bsdf demo -o out/demo "$@" ;;
    test)
        ensure_llvm; ensure_venv
        # two worker processes (pytest-xdist): the suite is mostly single-threaded Python and JIT
        # compilation, so the 2-core CI machine runs it in about half the time; HYDE_TEST_WORKERS=0
        # runs it in this one process
        exec .venv/bin/python -m pytest -n "${HYDE_TEST_WORKERS:-2}" --dist worksteal "$@" ;;
    wheel)
        ensure_llvm; ensure_venv
        exec tools/check_wheel.sh "$@" ;;
    *)
        echo "usage: ./run.sh demo | ./run.sh test [pytest args] | ./run.sh wheel [--validate]" >&2; exit 2 ;;
esac
