#!/usr/bin/env bash
# The line's load benchmark (see gateway/benches/line.rs): the real-time processes' wake-up
# latency with and without a busy remote client of the cell's gateway, alternating, with the
# ratios loaded/quiet at the end.
#   bash bench/line.sh [--rounds N] [--duration S] [--clients N]
# Run it as root (SCHED_FIFO, as a controller runs).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --bins --workspace
exec cargo bench -p gateway --bench line -- "$@"
