#!/usr/bin/env bash
# Reruns the performance page: the bevy_silk comparison (its own crate and
# lock file, outside the workspace), then `docs/perf.md` and its chart,
# which include the comparison's table. Release builds; run on an idle
# machine. The first run builds bevy_silk's Bevy (about 15 minutes on 2 cores).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo run --release --manifest-path compare/silk/Cargo.toml -- --out docs/perf/silk.md
cargo run --release -p bevy_cloth_report -- --perf --out docs
