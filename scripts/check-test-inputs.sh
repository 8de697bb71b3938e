#!/usr/bin/env bash
# Tests read only files in the repository (or files they generate, or files the set-up script
# fetched and verified): a clone on another machine has no ../shared and none of a developer's
# absolute paths, and a test that skips when its input is missing passes without testing.
# This fails when a test source names a path outside the repository.
# Usage: scripts/check-test-inputs.sh [DIR...]   (default: the repository's crates and services)
set -euo pipefail
cd "$(dirname "$0")/.."

# Absolute paths of development machines, the shared staging folder next to the clone, and
# relative paths that climb out of a crate (crates/X and services/X sit two levels deep).
pattern='(/work/|/root/|/home/|shared/assets|\.\./shared|(\.\./){3})'

# The pattern must catch what it is meant to catch, or this check would pass vacuously.
probe="$(mktemp)"
trap 'rm -f "$probe"' EXIT
printf '%s\n' 'const A: &str = "/work/shared/assets/heads/x.glb";' \
    'let p = dir.join("../../../shared/assets/hdri");' >"$probe"
if [ "$(grep -cE "$pattern" "$probe")" != 2 ]; then
    echo "check-test-inputs: the path pattern no longer matches its own examples" >&2
    exit 1
fi

dirs=("$@")
if [ ${#dirs[@]} -eq 0 ]; then
    dirs=(crates services ./tests)
fi
# Test code: the tests/ folders, plus unit tests inside src/ (files with a #[cfg(test)]).
mapfile -t files < <(
    find "${dirs[@]}" -path '*/tests/*.rs' -type f
    grep -rlE --include='*.rs' '#\[cfg\(test\)\]' "${dirs[@]}" || true
)
hits="$(grep -nE "$pattern" "${files[@]}" 2>/dev/null || true)"
if [ -n "$hits" ]; then
    echo "error: test sources name paths outside the repository:" >&2
    echo "$hits" >&2
    echo "commit the input under the crate's tests/data/ (with its licence) or generate it in the test" >&2
    exit 1
fi
echo "check-test-inputs: ${#files[@]} test sources read only repository files"
