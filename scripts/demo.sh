#!/usr/bin/env bash
# `make demo`: an experiment in simulation. Seeds a fresh embedded DB under runs/ with the scenario's seed, then
# runs its launch file recording the site's topics; everything lands in one run directory runs/<timestamp>/:
# the report (index.html, metrics.json, plots), the recording bag/ (rosbag2, MCAP: ros2 bag, Foxglove) and,
# once the launch has ended and the bag is closed, the report's replay page replay.html.
#   SCENARIO=paper (default): config/seeds/paper.yaml, config/launch/paper_experiment.yaml
#   SCENARIO=fleet:           config/seeds/fleet.yaml, config/launch/fleet.yaml (one ZX200 loads three carriers)
#   SCENARIO=design:          config/seeds/design_trench.yaml, config/launch/design_trench.yaml (the ZX200 digs the
#                             trench design of task 35 pass by pass over CAN); the plant writes its true height field
#                             to heights.npz, the launch's output goes to launch.log too (the task's end message),
#                             and tests/bench/bench_design_trench.py --report then writes the surface error against
#                             the design (truth and sensed) to design.json and design_error.png (figures:
#                             tms_rp/excavation/README.md)
#   SCENARIO=embankment:      as design, on config/seeds/design_embankment.yaml (task 36: the ZX200 cuts a two-faced
#                             embankment out of a soil pile), the same launch file with the pile's plant
#                             (config/sim/design_embankment_plant.yaml)
#   RECORD=0:                 no recording (and no replay page)
#   SEED=<name>:              another seed of config/seeds/ (`tms-db seed <name>`) instead of the scenario's
# A first argument (a launch file) replaces the scenario's launch file.
set -euo pipefail
cd "$(dirname "$0")/.."
SCENARIO=${SCENARIO:-paper}
case "$SCENARIO" in
  paper) DEFAULT_LAUNCH=config/launch/paper_experiment.yaml ;;
  fleet) DEFAULT_LAUNCH=config/launch/fleet.yaml ;;
  design) DEFAULT_LAUNCH=config/launch/design_trench.yaml; DEFAULT_SEED=design_trench ;;
  embankment) DEFAULT_LAUNCH=config/launch/design_trench.yaml; DEFAULT_SEED=design_embankment ;;
  *) echo "demo.sh: unknown SCENARIO=$SCENARIO (paper, fleet, design or embankment)" >&2; exit 2 ;;
esac
DESIGN=0
case "$SCENARIO" in design|embankment) DESIGN=1 ;; esac
SEED=${SEED:-${DEFAULT_SEED:-$SCENARIO}}
LAUNCH=${1:-$DEFAULT_LAUNCH}
shift || true
STAMP=$(date +%Y%m%d-%H%M%S)
RUN_DIR=${RUN_DIR:-$PWD/runs/$STAMP}
export TMS_DB_PATH=${TMS_DB_PATH:-$PWD/runs/db-$STAMP}
export ROS_AUTOMATIC_DISCOVERY_RANGE=${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}
mkdir -p "$TMS_DB_PATH" "$RUN_DIR"
.venv/bin/tms-db seed "$SEED"
ARGS=()
# the supervisor writes its report into the same run directory (its run_dir parameter), when the launch has one
if .venv/bin/tms-launch --list "$LAUNCH" | cut -f1 | grep -qx /tms_ur_experiment; then
  ARGS+=(--param "tms_ur_experiment:run_dir=$RUN_DIR")
fi
if [ "${RECORD:-1}" != 0 ]; then
  ARGS+=(--record "$RUN_DIR/bag")
fi
if [ "$DESIGN" = 1 ]; then
  ARGS+=(--param "sim_plant:heights_npz=$RUN_DIR/heights.npz")
fi
if [ "$SCENARIO" = embankment ]; then
  ARGS+=(--param "sim_plant:config=config/sim/design_embankment_plant.yaml" --param "tms_ur_experiment:task_ids=[36]")
fi
set +e
if [ "$DESIGN" = 1 ]; then
  # the task's end message (its pass count) is in the launch's output only: kept for the design figures
  .venv/bin/tms-launch "$LAUNCH" "${ARGS[@]}" "$@" 2>&1 | tee "$RUN_DIR/launch.log"
  rc=${PIPESTATUS[0]}
else
  .venv/bin/tms-launch "$LAUNCH" "${ARGS[@]}" "$@"
  rc=$?
fi
set -e
if [ "${RECORD:-1}" != 0 ] && [ -f "$RUN_DIR/bag/metadata.yaml" ]; then
  .venv/bin/python -m tms_ur.replay_page "$RUN_DIR" || echo "demo.sh: no replay page (see above)" >&2
fi
if [ "$DESIGN" = 1 ]; then
  .venv/bin/python -m tests.bench.bench_design_trench --report "$RUN_DIR" --seed "$SEED" || echo "demo.sh: no design figures (see above)" >&2
fi
echo "demo.sh: run directory $RUN_DIR"
exit $rc
