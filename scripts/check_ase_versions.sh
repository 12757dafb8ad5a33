#!/usr/bin/env bash
# Run the fast test subset (-m "not slow") against given ASE versions, each in a
# fresh virtual environment with the package and its test extras installed.
#
# Usage: scripts/check_ase_versions.sh [VERSION ...]
#        (default: the oldest ASE pyproject.toml declares, "ase>=X", and the newest on PyPI)
# Environment: WORKDIR (default: a new temporary folder) holds the environments and logs;
#              PYTEST_ARGS (default: "-n auto") is passed on to pytest.
# Exit status: 0 when every version passed; otherwise the number of versions that failed.
set -uo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
workdir="${WORKDIR:-$(mktemp -d -t rigidmd-ase-XXXXXX)}"
mkdir -p "$workdir"
if [ "$#" -eq 0 ]; then
    oldest="$(sed -n 's/.*"ase>=\([0-9.]*\).*/\1/p' "$repo/pyproject.toml" | head -n 1)"
    newest="$(python -m pip index versions ase 2>/dev/null | sed -n 's/^ase (\(.*\))$/\1/p')"
    set -- "${oldest:?no ase>=X in pyproject.toml}" \
        "${newest:?cannot find the newest ASE on the package index}"
fi
failed=0
for version in "$@"; do
    env="$workdir/ase-$version"
    log="$workdir/ase-$version.log"
    echo "ASE $version: environment $env, log $log"
    rm -rf "$env"
    if ! { python -m venv "$env" &&
           "$env/bin/python" -m pip install -q -e "$repo[test]" "ase==$version"; } >"$log" 2>&1; then
        echo "ASE $version: install FAILED (see $log)"
        failed=$((failed + 1))
        continue
    fi
    installed="$("$env/bin/python" -c 'import ase; print(ase.__version__)')"
    # Run from the repository so the tests find their data; the editable install
    # makes the environment import this checkout's src/.
    (cd "$repo" && "$env/bin/python" -m pytest -m "not slow" -q -p no:cacheprovider \
        ${PYTEST_ARGS:--n auto}) >>"$log" 2>&1
    status=$?
    summary="$(tail -n 1 "$log")"
    if [ "$status" -eq 0 ]; then
        echo "ASE $version (imported $installed): passed: $summary"
    else
        echo "ASE $version (imported $installed): FAILED (exit $status): $summary"
        failed=$((failed + 1))
    fi
done
exit "$failed"
