#!/bin/bash
# Issue 34's figures (2026-12-04, the 2-core machine; the insert exports and their replay rerun 2026-12-05 after the grip fixes; the pick exports, their doctor reports and replay rerun 2026-12-06 after the guarded descent): LeRobotDataset v3.0 exports of 50 scripted-expert episodes
# (lead velocity, open loop, 1 Hz, 200 ms, 6 s episodes, 2 mm noise, 10 % dropout: moving_target's defaults), seeds
# 2000-2049, 2 cameras (front, side) at 96 px and 224 px, 10 fps; each checked by lerobot-doctor (its JSON report
# beside the figure), read back frame by frame (--verify), and replayed through --source lerobot:DIR in open loop.
# Run from this folder; the datasets go to out/ (ignored by git).
set -e
cd "$(dirname "$0")"
mkdir -p out
col() { python -m scenarios.collect --format lerobot --source expert --episodes 50 --seed 2000 --verify --quiet "$@"; }
doctor() { lerobot-doctor check "out/$1" --ci --fail-on fail --json > "doctor_$1.json" 2> "doctor_$1.txt"; }
for px in 96 224; do
  col --out out/reach_linear_$px --target linear --image-size-px $px > reach_linear_$px.txt; doctor reach_linear_$px
  col --out out/pick_linear_$px --task pick --target linear --speed 0.2 --image-size-px $px > pick_linear_$px.txt
  doctor pick_linear_$px
  col --out out/insert_static_$px --task insert --target static --speed 0 --image-size-px $px > insert_static_$px.txt
  doctor insert_static_$px
done
col --out out/reach_static_96 --target static --speed 0 > reach_static_96.txt; doctor reach_static_96
# replay: the recorded actions through the stack, open loop, each episode's own seed (20 episodes each)
for ds in reach_static_96 reach_linear_96 pick_linear_96 insert_static_96; do
  python -m scenarios.lerobot_replay out/$ds --episodes 20 --quiet --json out/replay_$ds.json > replay_$ds.txt || true
done
# the action spaces and frame rates: joint_pos, 20 and 30 fps (interpolated, slerp), replayed
col --out out/reach_linear_joint_pos --target linear --action-space joint_pos --episodes 20 > reach_linear_joint_pos.txt
python -m scenarios.lerobot_replay out/reach_linear_joint_pos --quiet > replay_reach_linear_joint_pos.txt || true
for fps in 20 30; do
  col --out out/reach_linear_${fps}fps --target linear --fps $fps --episodes 20 > reach_linear_${fps}fps.txt
  python -m scenarios.lerobot_replay out/reach_linear_${fps}fps --quiet > replay_reach_linear_${fps}fps.txt || true
done
