#!/usr/bin/env bash
# Writes the sidecar (*.training_env.json) of every checkpoint of the table in README.md from the recordings here.
# Run from the repository root after record.sh.
set -e
D=results/training_envs
B="python eval/training_env.py backfill"
NOTE1="stage 1 (dca1c31 + uncommitted controller work): the code it ran is in no commit"
$B sofar_agents/checkpoints/pasta_lagunaseca_interactive.json --evidence $D/then_3134d23_interactive8.npz $D/now_interactive8.npz
$B sofar_agents/checkpoints/pasta_lagunaseca_paper.json --evidence $D/then_2ab0661_paper_stack.npz $D/now_paper_stack.npz
$B results/interactive_dense/pasta_midstart.json --evidence $D/then_2ab0661_interactive8.npz $D/now_interactive8.npz
$B results/interactive_dense/budget/pasta_midstart_800k.json --evidence $D/then_2ab0661_interactive8.npz \
    $D/now_interactive8.npz $D/then_e04e6af_interactive8.npz $D/now_interactive8.npz
$B results/paper_stack/budget/pasta_paper_800k.json --evidence $D/then_2ab0661_paper_stack.npz $D/now_paper_stack.npz \
    $D/then_aab5845_paper_stack.npz $D/now_paper_stack.npz
$B results/paper_stack/replicate/pasta_paper_seed72.json --evidence $D/then_dd04262_paper_stack.npz $D/now_paper_stack.npz
$B results/dynamic/pasta_dynamic.json --evidence $D/then_c24fe75_dynamic.npz $D/now_dynamic.npz \
    --unverified "stage 1 (8605e0d+dirty): the dynamic world was uncommitted work then; commit 8605e0d has no scenario 'dynamic'"
$B results/dynamic/pasta_dynamic_low.json --evidence $D/then_6c282d1_dynamic.npz $D/now_dynamic.npz
$B results/multi_agent/selfplay_lagunaseca.json --evidence $D/then_074fb0c_paper.npz $D/now_paper.npz \
    $D/then_bfadab9_race4.npz $D/now_race4.npz $D/then_8605e0d_race4.npz $D/now_race4.npz --unverified "$NOTE1"
