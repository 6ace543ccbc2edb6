#!/usr/bin/env bash
# The whole test suite: the Rust workspace (`cargo test --workspace`), then the Python
# package `dhct` built from crates/python into a venv under target/ and its pytest suite.
#
# The Python part is skipped, with the reason printed, only when python3 is absent; any
# other failure (no venv module, no network for pip, a build error, a failing test) fails
# the script. Extra arguments are passed to pytest (e.g. `-k correct`).
set -euo pipefail
cd "$(dirname "$0")/.."

cargo test --workspace

if ! command -v python3 >/dev/null 2>&1; then
    echo "test-all: skipping the Python package tests: python3 is not installed"
    exit 0
fi

venv=target/py-venv
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
py="$venv/bin/python"
# The independent readers the test_crosscheck_*.py tests compare with: gwyfile (.gwy),
# NSFopen (.nid), pySPM (Nanoscope), createc (Createc .dat), access2thematrix (MATRIX),
# SciFiReaders (WSxM); tifffile reads the corrected TIFFs' pixel size back.
"$py" -m pip install --quiet --disable-pip-version-check maturin numpy pytest pandas dask distributed \
    gwyfile NSFopen pySPM tifffile createc pyyaml access2thematrix SciFiReaders
# The dev profile reuses what `cargo test --workspace` just built; --force-reinstall
# rebuilds the package even when its version did not change.
MATURIN_PEP517_ARGS="--profile dev" "$py" -m pip install --quiet --disable-pip-version-check \
    --force-reinstall --no-deps ./crates/python

# The tests compare with the command line built above.
export DHCT_BIN="${CARGO_TARGET_DIR:-$PWD/target}/debug/dhct"
export PYTHONDONTWRITEBYTECODE=1
"$py" -m pytest -p no:cacheprovider crates/python/tests "$@"
