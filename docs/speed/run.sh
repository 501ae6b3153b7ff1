#!/bin/bash
# Issue 33's figures (2026-12-04; the floor and the look-ahead rerun 2026-12-05; the quiet 2-core machine, nothing else running; mink from `pip install -e '.[bench]'`)
set -e
# the floor beside our tick and mink's solve_ik (rerun 2026-12-05 afternoon after the command path's diet), on the main job's episode (our policy) and on the expert's
python -m mmact_ctrl.bench --floor --json floor_policy.json > floor_policy.txt
# the same on the other hosts of 2026-12-06 (an AMD EPYC, then an Intel Xeon in the evening): floor_policy_2026-12-06*.txt
# python -m mmact_ctrl.bench --floor --json floor_policy_2026-12-06_xeon.json > floor_policy_2026-12-06_xeon.txt
# and late that day again on an AMD EPYC host: floor_policy_2026-12-06_amd_late.txt (two more runs: tick/floor 2.64x, 2.62x)
python -m mmact_ctrl.bench --floor --floor-args "--source expert" --json floor_expert.json > floor_expert.txt
# the main job's real-time factor as the issue measured it
python -m scenarios.moving_target --mode hybrid --target linear --episodes 3 --seed 3 --json out/main_job.json
# the policy's call in a worker (mmact_ctrl.lookahead, 2026-12-05) against in line: twice in a row, same results
for i in 1 2; do for f in --no-lookahead ""; do
  python -m scenarios.moving_target --mode hybrid --target linear --episodes 4 --seed 3 --quiet $f --json out/main_job$f.json
done; done
# the sweep's scaling: 75 episodes with 1 and with 2 workers, the whole process tree's CPU time, results compared
# (stop 55: scenarios.sweep_scaling; before it /usr/bin/time, which does not count the fork server's workers)
python -m mmact_ctrl.bench --sweep --json sweep_quick_local.json > sweep_quick_local.txt
# and on a local Ray cluster of 2 CPUs too (it idles beside the local runs), on --quick and on a 150-episode study
# (open_loop, receding, hybrid x linear, reversal x 25 seeds, 6 s)
ray start --head --num-cpus 2 --include-dashboard=false
python -m mmact_ctrl.bench --sweep --sweep-args "--ray-address auto" --json sweep_quick.json > sweep_quick.txt
python -m mmact_ctrl.bench --sweep --sweep-args "--grid scale_grid.json --ray-address auto" --json sweep_scale_grid.json > sweep_scale_grid.txt
ray stop
