#!/usr/bin/env bash
# The servo-rate benchmark (see supervisor/benches/rates.rs): the triangle on the real
# processes with servo and the drives at 1 kHz and at 4 kHz, alternating, with the medians and
# the ratios 4 kHz / 1 kHz at the end.
#   bash bench/rates.sh [--rounds N]
# Needs root for SCHED_FIFO and mlockall (without it every process runs under SCHED_OTHER).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --bins
exec cargo bench -p supervisor --bench rates -- "$@"
