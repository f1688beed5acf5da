#!/usr/bin/env bash
# The EtherCAT benchmark (see supervisor/benches/ethercat.rs): the triangle on the same cell
# with its drives in shared memory (machine-sim) and on the emulated bus, at 1 kHz and 4 kHz,
# alternating, with the medians and the ratios EtherCAT / shared memory at the end.
#   bash bench/ethercat.sh [--rounds N]
# Needs root: each run in a network namespace of its own, SCHED_FIFO.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --bins --workspace
exec cargo bench -p supervisor --bench ethercat -- "$@"
