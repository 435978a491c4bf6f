#!/usr/bin/env bash
# bench/monitor.sh - `ferrobus monitor`'s redraw time for a 200-cell grid (goal: under 1 ms a
# frame). Runs the ignored test monitor::tests::bench_redraw_of_a_200_cell_grid in a release
# build: two panes of 100 registers, every value changed before each frame, 2,000 frames on a
# 160x60 screen through ratatui's diff into crossterm's escape sequences (to a sink, so the
# terminal emulator's own time is not in it). Prints the median, p90, p99 and max.
# Record the result in bench/MONITOR.md with the machine and its load.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
export CARGO_INCREMENTAL=0
PROFILE="${PROFILE:-release}"
uptime
cargo test --profile "$PROFILE" -p ferrobus-cli --bin ferrobus monitor::tests::bench_redraw_of_a_200_cell_grid \
    -- --ignored --nocapture --test-threads 1 2>&1 | grep -E "redraw of|test result"
