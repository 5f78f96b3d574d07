#!/usr/bin/env bash
# `make demo`: the paper experiment in simulation. Seeds a fresh embedded DB under runs/, then runs
# config/launch/paper_experiment.yaml; the report lands in runs/<timestamp>/.
set -euo pipefail
cd "$(dirname "$0")/.."
LAUNCH=${1:-config/launch/paper_experiment.yaml}
shift || true
export TMS_DB_PATH=${TMS_DB_PATH:-$PWD/runs/db-$(date +%Y%m%d-%H%M%S)}
export ROS_AUTOMATIC_DISCOVERY_RANGE=${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}
mkdir -p "$TMS_DB_PATH"
.venv/bin/tms-db seed paper
exec .venv/bin/tms-launch "$LAUNCH" "$@"
