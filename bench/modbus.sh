#!/usr/bin/env bash
# The Modbus load benchmark (see modbus/benches/load.rs): the real-time processes' wake-up
# latency with and without Modbus clients hammering the server, alternating, with the ratios
# loaded/quiet at the end.
#   bash bench/modbus.sh [--rounds N] [--duration S] [--clients N] [--interval-ms N]
# Run it as root (SCHED_FIFO, as a controller runs).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --bins --workspace
exec cargo bench -p modbus --bench load -- "$@"
