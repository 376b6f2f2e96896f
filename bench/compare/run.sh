#!/usr/bin/env bash
# Side-by-side benchmarks of ambid against its Python peers (issue 9), in one run.
#
#   bench/compare/run.sh [compare.py options, e.g. --reps 5 --tasks welch,frf]
#
# 1. creates (or reuses) a Python venv with the pinned peers of requirements.txt
#    ($AMBID_COMPARE_VENV, default bench/compare/.venv; PYTHON picks the interpreter, default python3);
# 2. builds ambid and the in-process timing program `compare_tasks` in release mode;
# 3. generates the data with `ambid simulate` and converts the real data sets of ../shared/data/real;
# 4. runs every task alternately in ambid and in the peer and rewrites the table between
#    `<!-- compare:begin -->` and `<!-- compare:end -->` in docs/benchmarks.md.
# With --python it also builds the release wheel of the Python package (crates/ambid-py, by
# maturin, into the same venv) and runs every ambid task a third way, through `import ambid`;
# that table goes between `<!-- compare-py:begin -->` and `<!-- compare-py:end -->`.
# Not part of CI (it installs packages from PyPI and takes 15-30 minutes).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
venv="${AMBID_COMPARE_VENV:-$here/.venv}"
python="${PYTHON:-python3}"

if [ ! -x "$venv/bin/python" ]; then
    echo "creating the venv $venv" >&2
    "$python" -m venv "$venv"
fi
# pip is a no-op when the pinned versions are already installed
"$venv/bin/python" -m pip install -q --disable-pip-version-check -r "$here/requirements.txt"

target="${CARGO_TARGET_DIR:-$root/target}"
echo "building ambid (release) into $target" >&2
(cd "$root" && cargo build --release --locked -q --bin ambid --example compare_tasks)

for a in "$@"; do
    if [ "$a" = "--python" ]; then
        echo "building the ambid wheel (release) and installing it into $venv" >&2
        "$venv/bin/python" -m pip install -q --disable-pip-version-check "maturin>=1.7,<2"
        rm -rf "$target/wheels-compare"
        (cd "$root" && "$venv/bin/maturin" build --quiet --release -m crates/ambid-py/Cargo.toml \
            -o "$target/wheels-compare")
        "$venv/bin/python" -m pip install -q --disable-pip-version-check --force-reinstall \
            --no-deps "$target"/wheels-compare/ambid-*.whl
    fi
done

exec "$venv/bin/python" "$here/compare.py" \
    --ambid "$target/release/ambid" \
    --example "$target/release/examples/compare_tasks" "$@"
