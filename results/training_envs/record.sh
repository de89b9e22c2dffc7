#!/usr/bin/env bash
# Re-makes the recordings of this folder: each training environment under a checkout of its training commit
# (then_*.npz) and under the current code with the name it has today (now_*.npz). Run from the repository root.
set -euo pipefail
D=results/training_envs
then_() {  # commit, name, checkpoint
  local dir=/tmp/sofar_replay_$1
  [ -d "$dir" ] || git worktree add -f "$dir" "$1" --detach >/dev/null
  PYTHONPATH="$dir" python eval/training_env.py record --checkpoint "$3" --out "$D/then_$1_$2.npz"
}
# The first single-car policy as it was before it was re-trained with "sofar-1" (its JSON at f9726b0): the first
# stage of the self-play policy continued it.
OLD=$(mktemp --suffix=.json) && git show f9726b0:sofar_agents/checkpoints/pasta_lagunaseca.json > "$OLD"
then_ 074fb0c paper "$OLD"
then_ 3134d23 interactive8 sofar_agents/checkpoints/pasta_lagunaseca_interactive.json
then_ 2ab0661 paper_stack sofar_agents/checkpoints/pasta_lagunaseca_paper.json
then_ 2ab0661 interactive8 results/interactive_dense/pasta_midstart.json
then_ e04e6af interactive8 results/interactive_dense/budget/pasta_midstart_800k.json
then_ aab5845 paper_stack results/paper_stack/budget/pasta_paper_800k.json
then_ dd04262 paper_stack results/paper_stack/replicate/pasta_paper_seed72.json
then_ c24fe75 dynamic results/dynamic/pasta_dynamic.json
then_ 6c282d1 dynamic results/dynamic/pasta_dynamic_low.json
then_ bfadab9 race4 results/multi_agent/selfplay_lagunaseca.json
then_ 8605e0d race4 results/multi_agent/selfplay_lagunaseca.json
then_ bf41b6a paper_stack sofar_agents/checkpoints/pasta_lagunaseca_paper.json  # the commit of results/paper_stack/avx2
now_() {  # name, checkpoint, keyword arguments as named today
  local name=$1 ckpt=$2; shift 2
  python eval/training_env.py record --checkpoint "$ckpt" --out "$D/now_$name.npz" "$@"
}
now_ paper "$OLD" --set stack=sofar-1
now_ interactive8 sofar_agents/checkpoints/pasta_lagunaseca_interactive.json --set stack=sofar-1
now_ paper_stack sofar_agents/checkpoints/pasta_lagunaseca_paper.json
now_ dynamic results/dynamic/pasta_dynamic.json --set stack=sofar-1
now_ race4 results/multi_agent/selfplay_lagunaseca.json --set stack=sofar-1
