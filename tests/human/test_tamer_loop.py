"""DDPG + DeepTAMER through the real queue on the toy env.

The end-to-end test (slow): a simulated keyboard teacher who wants the point to move up (+1 when
action[1] > 0.2, -1 when < -0.2) - something the env's reward does not ask for - feeds the real
FeedbackQueue; events are credited on the step clock and train the reward model, whose params enter every
DDPG chunk. Against DDPG alone with the same seeds, the deterministic actor's mean vertical action on test
episodes must rise by at least 0.15 (measured +0.23: 0.03 -> 0.26, beta 1.0).
"""

import numpy as np
import pytest

from mjx_protamer.envs.toy import PointReachEnv
from mjx_protamer.human.queue import FeedbackLog
from mjx_protamer.human.tamer_loop import TamerRun, load_feedback_config, rollout_actions

TOY = ["pretrain.env_name=toy", "pretrain.ddpg.actor_hidden=[64,64]", "pretrain.ddpg.critic_hidden=[64,64]",
       "pretrain.ddpg.reward_beta=1.0", "pretrain.ddpg.replay_size=20000", "pretrain.ddpg.tau=0.005",
       "pretrain.train.num_envs=4", "pretrain.train.episode_length=50", "pretrain.train.warmup_env_steps=800",
       "pretrain.train.chunk_steps=100", "feedback.dt=0.05", "feedback.reward_model.hidden=[64,64]",
       "feedback.credit.min_interval_steps=2", "feedback.teacher.min_gap_steps=2", "feedback.teacher.give_rate=0.5",
       "feedback.teacher.rule=[{signal: 'action:1', value: 1.0, above: 0.2}, "
       "{signal: 'action:1', value: -1.0, below: -0.2}]"]


def test_loop_smoke_events_flow_from_teacher_to_reward_model(tmp_path):
    cfg = load_feedback_config(None, TOY + ["pretrain.train.total_env_steps=1200", "pretrain.train.warmup_env_steps=400",
                                            "pretrain.ddpg.actor_hidden=[16]", "pretrain.ddpg.critic_hidden=[16,16]",
                                            "feedback.reward_model.hidden=[16]", "feedback.credit.silence_weight=0.03"])
    run = TamerRun(cfg, PointReachEnv(cfg.pretrain.toy), feedback="simulated:keyboard", log_path=tmp_path / "fb.jsonl")
    before = run.model.predict(np.zeros((1, 6)), np.array([[0.0, 1.0]]))
    for _ in range(cfg.pretrain.train.num_chunks):
        m = run.step_chunk()
    run.close()
    assert run.events > 10 and run.credited > run.events and run.model.updates >= run.events
    assert m["queue_overflow"] == 0 and m["queue_rejected"] == 0
    logged = FeedbackLog.read(tmp_path / "fb.jsonl")
    assert len(logged) == run.events and all(e.source == "simulated" for e in logged)
    # every event judged a step the learner showed earlier
    assert all(e.details["about_step"] < run.first_step for e in logged)
    assert not np.allclose(before, run.model.predict(np.zeros((1, 6)), np.array([[0.0, 1.0]])))
    # the teacher gives only +-1: the 0 rows are the steps it watched in silence, judged once their window closed
    buf = run.model.buffer
    zero = buf.target[:buf.size] == 0
    assert zero.any() and np.allclose(buf.weight[:buf.size][zero], 0.03)
    assert run.silent_next <= run.first_step - run.silence_reach / cfg.feedback.dt + 1


def test_the_host_loop_refuses_silences_gated_by_an_attention_signal_it_lacks():
    from mjx_protamer.config import ConfigError

    cfg = load_feedback_config(None, TOY + ["feedback.credit.silence_needs_attention=true"])
    with pytest.raises(ConfigError, match="silence_needs_attention"):
        TamerRun(cfg, PointReachEnv(cfg.pretrain.toy), feedback="simulated:keyboard")


@pytest.mark.slow
def test_tamer_with_simulated_keyboard_teacher_moves_behaviour_its_way():
    cfg = load_feedback_config(None, TOY + ["pretrain.train.total_env_steps=12000"])
    env = PointReachEnv(cfg.pretrain.toy)
    vertical = {}
    for fb in (None, "simulated:keyboard"):
        run = TamerRun(cfg, env, feedback=fb)
        for _ in range(cfg.pretrain.train.num_chunks):
            run.step_chunk()
        out = rollout_actions(run.trainer, env, run.state.actor_params, 16, 50, seed=123)
        vertical[fb] = float(out["action"][..., 1].mean())
    print(f"mean vertical action: DDPG {vertical[None]:+.3f}, DDPG+DeepTAMER {vertical['simulated:keyboard']:+.3f}")
    assert vertical["simulated:keyboard"] > vertical[None] + 0.15
