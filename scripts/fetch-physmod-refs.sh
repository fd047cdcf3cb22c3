#!/bin/sh
# Fetch RoboTool's physmod library and its metamodel-coverage models (UoY-RoboStar/robotool-meta-physmod)
# to a folder OUTSIDE this repository, for tests/test_physmod_refs.py:
#   scripts/fetch-physmod-refs.sh /work/refs/physmod
#   COTWIN_PHYSMOD_REFS=/work/refs/physmod .venv/bin/python -m pytest -q -s tests/test_physmod_refs.py
# The files are RoboTool's, not cotwin's: never commit them. Needs git and network access to github.com.
set -eu
dest=${1:?usage: $0 DEST (a folder outside the repository)}
repo=${PHYSMOD_REPO:-https://github.com/UoY-RoboStar/robotool-meta-physmod}
lib=physmod-libs/circus.robocalc.robosim.physmod.libs.textual/lib/physmod
cov=physmod-testdata/circus.robocalc.robosim.physmod.testdata/testdata/integration/T3/metamodelCoverage
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
git clone --quiet --depth 1 --filter=blob:none --sparse "$repo" "$work/repo"
git -C "$work/repo" sparse-checkout set "$lib" "$cov"
mkdir -p "$dest/lib" "$dest/metamodelCoverage"
cp -R "$work/repo/$lib" "$dest/lib/"
cp -R "$work/repo/$cov/." "$dest/metamodelCoverage/"
echo "$(find "$dest" -type f | wc -l) files in $dest"
