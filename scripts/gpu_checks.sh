#!/usr/bin/env bash
# The GPU checks in one go (issue 40), within 10 minutes on one GPU: the MJX env at batch 1-8192, the batched
# DDPG trainer against its roofline (1 and 5 vmapped seeds, MJX), and a 5-seed Table II condition (DTK, the
# built-in default). Each step has its own time limit, so a slow step cannot eat the others' time; its JSON
# (table2: OUT/table2_dtk/table2.json, with each condition's wall time) and log land in OUT, with the device each ran on (`machine.device_kind`), ready for docs/environment.md.
#
#   bash scripts/gpu_checks.sh OUT            # on a machine whose JAX sees a GPU
#   bash scripts/gpu_checks.sh --quick --allow-cpu OUT   # the same steps, tiny, on a CPU (a smoke run)
#
# Without --allow-cpu it stops at once, with one line, when JAX sees no GPU: a CPU figure filed as a GPU one
# would be worse than none.
set -uo pipefail
quick=0 allow_cpu=0 out=""
for arg in "$@"; do
  case "$arg" in
    --quick) quick=1 ;;
    --allow-cpu) allow_cpu=1 ;;
    -*) echo "gpu_checks: unknown option $arg (use --quick, --allow-cpu, then OUT)" >&2; exit 2 ;;
    *) out="$arg" ;;
  esac
done
if [ -z "$out" ]; then
  echo "gpu_checks: give an output folder: bash scripts/gpu_checks.sh [--quick] [--allow-cpu] OUT" >&2
  exit 2
fi
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
py="${PYTHON:-$root/.venv/bin/python}"
if [ ! -x "$py" ]; then
  echo "gpu_checks: no Python at $py: run the README's set-up first (or set PYTHON)" >&2
  exit 2
fi
backend="$("$py" -c 'import jax; print(jax.default_backend())' 2>/dev/null)"
if [ "$backend" != "gpu" ] && [ "$allow_cpu" != 1 ]; then
  echo "gpu_checks: JAX sees no GPU (backend '${backend:-none}'): install jax[cuda12] on a GPU machine, or pass --allow-cpu for a smoke run" >&2
  exit 2
fi
mkdir -p "$out" || { echo "gpu_checks: cannot create $out" >&2; exit 2; }
cd "$root"
protamer=("$py" -m mjx_protamer.cli)
command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi > "$out/nvidia-smi.txt" 2>&1

if [ "$quick" = 1 ]; then
  env_args=(--quick)
  train_args=(--env toy --skip-sb3 --steps 50 --batched-envs 16 --batched-iterations 5 --repeats 1
              --roofline-seeds 1,2 --roofline-chunks 1 --roofline-set env_name=toy --roofline-set train.num_envs=8
              --roofline-set train.episode_length=25 --roofline-set train.total_env_steps=4000
              --roofline-set train.warmup_env_steps=80 --roofline-set train.chunk_steps=10
              --roofline-set ddpg.replay_size=1000 --roofline-set 'ddpg.actor_hidden=[32,32]'
              --roofline-set 'ddpg.critic_hidden=[32,32]')
  table2_args=(--seeds 2 --set pretrain.train.total_env_steps=1280 --set pretrain.train.warmup_env_steps=320
               --set pretrain.train.chunk_steps=10 --set pretrain.train.eval_episodes=1
               --set pretrain.train.episode_length=100 --set pretrain.env.episode_length=100)
  limits=(300 300 300)
else
  env_args=(--batch-sizes 1,64,512,4096,8192 --steps 100 --repeats 3 --twin-steps 200 --fidelity-episodes 1
            --fidelity-steps 100)
  train_args=(--skip-sb3 --backends mjx --steps 500 --batched-envs 4096 --batched-iterations 20 --repeats 3
              --roofline-seeds 1,5 --roofline-chunks 3)
  table2_args=(--seeds 5)
  limits=(200 180 200)
fi

status=0
run_step() {  # name, limit, stdout file, command...: its stdout to OUT/<file>, its stderr to OUT/name.log
  local name="$1" limit="$2" stdout="$3"; shift 3
  local start=$SECONDS
  timeout "$limit" "$@" > "$out/$stdout" 2> "$out/$name.log"
  local rc=$?
  echo "{\"step\": \"$name\", \"rc\": $rc, \"timed_out\": $([ $rc = 124 ] && echo true || echo false), \"wall_s\": $((SECONDS - start))}" \
    >> "$out/steps.jsonl"
  echo "gpu_checks: $name rc $rc in $((SECONDS - start)) s (limit $limit s)" >&2
  [ $rc = 0 ] || status=1
}

run_step bench_env "${limits[0]}" bench_env.json "${protamer[@]}" bench env --json "${env_args[@]}"
run_step bench_train "${limits[1]}" bench_train.json "${protamer[@]}" bench train --json "${train_args[@]}"
# Table II's keyboard condition on 5 vmapped seeds (the built-in default's teacher, credit and reward model).
run_step table2_dtk "${limits[2]}" table2_dtk.out "${protamer[@]}" reproduce table2 --quiet --out "$out/table2_dtk" \
  --set 'conditions=[{name: DTK, channel: keyboard, credit: channel}]' "${table2_args[@]}"
echo "gpu_checks: results in $out (steps.jsonl says what finished)" >&2
exit $status
