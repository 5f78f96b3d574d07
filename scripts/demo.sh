#!/usr/bin/env bash
# `make demo`: an experiment in simulation. Seeds a fresh embedded DB under runs/ with the scenario's seed, then
# runs its launch file; the report lands in runs/<timestamp>/.
#   SCENARIO=paper (default): config/seeds/paper.yaml, config/launch/paper_experiment.yaml
#   SCENARIO=fleet:           config/seeds/fleet.yaml, config/launch/fleet.yaml (one ZX200 loads three carriers)
# A first argument (a launch file) replaces the scenario's launch file.
set -euo pipefail
cd "$(dirname "$0")/.."
SCENARIO=${SCENARIO:-paper}
case "$SCENARIO" in
  paper) DEFAULT_LAUNCH=config/launch/paper_experiment.yaml ;;
  fleet) DEFAULT_LAUNCH=config/launch/fleet.yaml ;;
  *) echo "demo.sh: unknown SCENARIO=$SCENARIO (paper or fleet)" >&2; exit 2 ;;
esac
LAUNCH=${1:-$DEFAULT_LAUNCH}
shift || true
export TMS_DB_PATH=${TMS_DB_PATH:-$PWD/runs/db-$(date +%Y%m%d-%H%M%S)}
export ROS_AUTOMATIC_DISCOVERY_RANGE=${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}
mkdir -p "$TMS_DB_PATH"
.venv/bin/tms-db seed "$SCENARIO"
exec .venv/bin/tms-launch "$LAUNCH" "$@"
