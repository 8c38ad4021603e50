"""Build the env a run config names (the self-touch MJX env, or the toy point-reach problem)."""

from __future__ import annotations


def make_env(config):
    """`config` has `env_name` and the matching section (`env` for self_touch, `toy` for toy)."""
    if config.env_name == "toy":
        from mjx_protamer.envs.toy import PointReachEnv

        return PointReachEnv(config.toy)
    from mjx_protamer.envs.self_touch import SelfTouchEnv

    return SelfTouchEnv(config.env)
