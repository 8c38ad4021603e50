"""Re-score a finished table2 run's agents under another teacher rule, without training again.

A table2 run keeps every condition's agents (`agents/<condition>/`, the tested actor of each seed) and reward
models. This runs those actors' test episodes again (the same test seeds as the run, so the behaviour metrics
are the run's own) and scores them with the hidden score of another rule: what a policy trained to please
one teacher does in the eyes of another (does the keyboard's right-hand policy also tour the body?), and each
new rule's baseline without retraining DDPG (about 17 minutes for 10 seeds on 2 cores).

The rule is the `feedback.teacher.rule` of a table2 YAML (`--config`; none: the built-in default's). Everything
else (env, seeds, test episodes, reward models) is the run's. The reward models were trained on the run's
teacher, so under another rule `r_hat_corr_*` says how far that model happens to track the new rule's score.
Outputs in `out`: table2.json and table2.md in `reproduce table2`'s layout (the teacher-score contrasts against
the baseline included), eval_<condition>_seed<k>.json and config.yaml (the run's config with the new rule),
and `rescored` in table2.json naming the run and the rule's source.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import jax
import numpy as np

from mjx_protamer.atomic import write_atomic
from mjx_protamer.config import ConfigError, to_dict
from mjx_protamer.experiments.env_factory import make_env
from mjx_protamer.experiments.feedback_train import make_feedback_train
from mjx_protamer.experiments.table2 import (load_condition_models, summarize, format_markdown, load_condition_agents,
                                             load_table2_config, make_seed_evaluator, pooled_corr)


def finished_conditions(run: Path, cfg) -> list[str]:
    """The conditions of the run that finished (their results file is there), in the run's order."""
    names = [c.name for c in cfg.conditions if (run / f"condition_{c.name}.json").is_file()]
    if not names:
        raise ConfigError(f"{run} holds no finished condition (condition_<name>.json): give the --out directory "
                          f"of a table2 run that finished at least one condition")
    return names


def rescore_table2(run, rule_config=None, out=None, overrides=None, progress: bool = True) -> dict:
    """Test the agents of table2 run `run` again and score them under the rule of `rule_config` (a table2
    YAML; None: the built-in default's); write the summary to `out` (default: `run`/rescore-<time>)."""
    import yaml

    run = Path(run)
    if not (run / "config.yaml").is_file():
        raise ConfigError(f"{run / 'config.yaml'} is missing: give the --out directory of a table2 run")
    cfg = load_table2_config(run / "config.yaml")
    rule = load_table2_config(rule_config, overrides).feedback.teacher.rule
    cfg = dataclasses.replace(cfg, feedback=dataclasses.replace(
        cfg.feedback, teacher=dataclasses.replace(cfg.feedback.teacher, rule=rule)))
    names = finished_conditions(run, cfg)
    cfg = dataclasses.replace(cfg, conditions=tuple(c for c in cfg.conditions if c.name in names))
    out = Path(out) if out is not None else run / time.strftime("rescore-%Y%m%d-%H%M%S")
    if (out / "table2.json").is_file():
        raise ConfigError(f"{out} already holds a summary; give another --out")

    t0 = time.perf_counter()
    pre = cfg.pretrain
    env = make_env(pre)
    ft = make_feedback_train(pre, env, cfg.feedback, cfg.batched)  # a rule signal this env lacks: ConfigError
    untrained = jax.jit(jax.vmap(ft.init))(np.asarray(cfg.seeds, np.uint32)).rm_params
    evaluate = make_seed_evaluator(cfg, env, ft)
    evals, wall, reward_models, samples = {}, {}, {}, {}
    for name in names:
        kept = json.loads((run / f"condition_{name}.json").read_text())
        _, _, agents = load_condition_agents(run, cfg, name, env.observation_size, env.action_size)
        reward_models[name], _ = load_condition_models(run, name, untrained)
        results, samples[name] = evaluate(agents["actor"], reward_models[name], untrained)
        evals[name] = {}
        for seed, ev in zip(cfg.seeds, results):
            ev["feedback"] = kept["evals"][str(seed)]["feedback"]  # what the run's own teacher gave
            evals[name][seed] = ev
        wall[name] = [kept["train_wall_s"]]
        if progress:
            print(f"[{name}] teacher score {np.mean([ev['teacher_score'] for ev in results]):+.3f} under the new "
                  f"rule ({time.perf_counter() - t0:.0f} s)", flush=True)
    for name, per_seed in pooled_corr(ft, reward_models, untrained, samples).items():
        for seed, extra in zip(cfg.seeds, per_seed):
            evals[name][seed].update(extra)
    summary = summarize(cfg, evals, wall, time.perf_counter() - t0)
    summary["rescored"] = {"run": str(run), "rule_from": str(rule_config) if rule_config else "built-in default",
                           "rule": [dataclasses.asdict(c) for c in rule],
                           "note": "the run's agents tested again; teacher_score and r_hat_corr_* under this rule, "
                                   "train_wall_s and feedback are the run's"}
    out.mkdir(parents=True, exist_ok=True)
    write_atomic(out / "config.yaml", yaml.safe_dump(to_dict(cfg), sort_keys=False))
    for name in names:
        for seed in cfg.seeds:
            write_atomic(out / f"eval_{name}_seed{seed}.json", json.dumps(evals[name][seed], indent=2))
    write_atomic(out / "table2.json", json.dumps(summary, indent=2))
    md = (f"Re-scored: the agents of {run} tested again under the rule from {summary['rescored']['rule_from']} "
          f"(training figures are the run's).\n\n" + format_markdown(summary))
    write_atomic(out / "table2.md", md)
    return {"out_dir": str(out), "table_md": str(out / "table2.md"), "table_json": str(out / "table2.json"),
            "summary": summary}
