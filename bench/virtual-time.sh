#!/usr/bin/env bash
# The virtual clock's benchmark (see supervisor/benches/virtual_time.rs): the seed's triangle on
# the wall clock and on the virtual clock, alternating, with the speed-up and the largest
# difference between their setpoints at the end.
#   bash bench/virtual-time.sh [--rounds N]
# Needs root for SCHED_FIFO and mlockall (without it every process runs under SCHED_OTHER).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --bins
exec cargo bench -p supervisor --bench virtual_time -- "$@"
