#!/usr/bin/env bash
# The latency benchmark (see latency/benches/compare.rs): cyclictest against our timer, a raw
# pipe against our IPC hop, alternating, with the ratios ours/baseline at the end.
#   bash bench/latency.sh [--rounds N] [--duration S] [--interval-us N] [--priority P]
# Needs root (SCHED_FIFO, mlockall) and cyclictest (apt-get install rt-tests).
set -euo pipefail
cd "$(dirname "$0")/.."
command -v cyclictest >/dev/null || { echo "cyclictest not found: apt-get install rt-tests" >&2; exit 1; }
cargo build --release -p supervisor
exec cargo bench -p latency --bench compare -- "$@"
