#!/bin/sh
# SHA-256 of what clsmap makes from fixed input: the five built-in worlds
# explored on the virtual clock, the CSAIL log and the recorded fixture
# mapped offline. Run it on two commits and diff the output: a refactor
# that keeps the behaviour prints the same lines.
#
#     scripts/fingerprint.sh > before.txt; git checkout …; scripts/fingerprint.sh | diff before.txt -
set -eu
cd "$(dirname "$0")/.."
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
cargo build --release --quiet --bin clsmap --example virtual_runs
target/release/examples/virtual_runs "$out/worlds" >/dev/null
csail=../shared/datasets/mit-csail/mit-csail.clf
if [ -f "$csail" ]; then
  target/release/clsmap map "$csail" --out "$out/csail" -q >/dev/null 2>&1
else
  echo "note: $csail not found; the CSAIL map is not fingerprinted" >&2
fi
target/release/clsmap map fixtures/csail-0000-0200.rec --out "$out/fixture" -q >/dev/null 2>&1
cd "$out"
find . -type f | LC_ALL=C sort | xargs sha256sum
