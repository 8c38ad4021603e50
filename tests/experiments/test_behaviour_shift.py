"""End to end, in the default suite: a simulated keyboard teacher moves behaviour its way.

On the toy env (fast to compile), the hidden rule wants the point to move up (+1 when action[1] > 0.2, -1
when < -0.2), which the env's own reward does not ask for. `reproduce table2` runs DDPG alone and DTK
(keyboard channel, channel-delay credit) on the same 5 seeds, vmapped in one program. DTK's teacher score
on test episodes must beat DDPG's by more than the sum of the two 95% confidence half-widths, and the
learned reward model must score the approved behaviour on the held-out test states above zero, and the
correlation columns must be reported (undefined where the test states all earn one score: here DTK's
deterministic actor always moves up).
"""

import json

import yaml

from mjx_protamer.cli import main

CONFIG = {
    "pretrain": {
        "env_name": "toy",
        "ddpg": {"actor_hidden": [32, 32], "critic_hidden": [32, 32], "replay_size": 8000, "batch_size": 32,
                 "tau": 0.005, "reward_beta": 1.0},
        "train": {"num_envs": 4, "episode_length": 50, "total_env_steps": 2000, "warmup_env_steps": 400,
                  "chunk_steps": 100, "eval_episodes": 4},
    },
    "feedback": {
        "dt": 0.05,
        "credit": {"min_interval_steps": 2},
        "reward_model": {"hidden": [32, 32]},
        "teacher": {"min_gap_steps": 2, "give_rate": 0.5, "threshold": 0.5,
                    "rule": [{"signal": "action:1", "value": 1.0, "above": 0.2},
                             {"signal": "action:1", "value": -1.0, "below": -0.2}]},
    },
    "conditions": [{"name": "DDPG", "channel": "none"}, {"name": "DTK", "channel": "keyboard"}],
    "seeds": [0, 1, 2, 3, 4],
}


def test_keyboard_teacher_shifts_behaviour_beyond_seed_noise(tmp_path):
    cfg = tmp_path / "shift.yaml"
    cfg.write_text(yaml.safe_dump(CONFIG))
    out = tmp_path / "shift"
    assert main(["reproduce", "table2", "--config", str(cfg), "--out", str(out), "--quiet"]) == 0
    c = json.loads((out / "table2.json").read_text())["conditions"]
    ddpg, dtk = c["DDPG"]["teacher_score"], c["DTK"]["teacher_score"]
    assert len(dtk["seed_values"]) == 5 and dtk["ci95"] is not None
    assert dtk["mean"] - ddpg["mean"] > dtk["ci95"] + ddpg["ci95"], (ddpg, dtk)
    assert dtk["mean"] > 0.5 and min(dtk["seed_values"]) > max(ddpg["seed_values"])  # every seed, not on average
    assert set(c["DTK"]) >= {"r_hat_corr_test", "r_hat_corr_untrained"}
    assert c["DDPG"]["feedback"]["feedback_total"] == 0 and c["DTK"]["feedback"]["feedback_total"] > 100
