# Sourced by scripts/second-car.sh and scripts/third-car.sh: the paper-sized training set.
#
#   simulate_paper_set CATMODEL VEHICLE DIR
#
# simulates, on the plant VEHICLE with its own receiver, the eight scenarios with seed 1 into
# DIR/seed1, straight-2.5/5/10 with seed 2 into DIR/seed2 (11 one-minute drives, as the paper's
# set: sim::scenario::PAPER_SIZED_TRAINING) and the 5-minute validation drive with seed 3 into
# DIR. The training logs are then "$DIR"/seed1/*[0-9t].csv "$DIR"/seed2/*[0-9].csv.
simulate_paper_set() {
  local b=$1 vehicle=$2 dir=$3 s
  mkdir -p "$dir/seed1" "$dir/seed2"
  for s in straight-2.5 straight-5 straight-7.5 straight-10 turn-left turn-right circle-left circle-right; do
    "$b" simulate-drive --scenario "$s" --seed 1 --vehicle "$vehicle" --out "$dir/seed1" 2>/dev/null
  done
  for s in straight-2.5 straight-5 straight-10; do
    "$b" simulate-drive --scenario "$s" --seed 2 --vehicle "$vehicle" --out "$dir/seed2" 2>/dev/null
  done
  "$b" simulate-drive --scenario validation --seed 3 --vehicle "$vehicle" --out "$dir" 2>/dev/null
}
