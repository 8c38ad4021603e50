"""Configuration of the self-touch environment: every knob in one place (validated)."""

from __future__ import annotations

import dataclasses

from mjx_protamer.config import check
from mjx_protamer.envs import body
from mjx_protamer.envs.body import PhysicsConfig

_SIDES = ("left", "right")
_ARM = ("shoulder_horizontal", "shoulder_ad_ab", "shoulder_rotation", "elbow")
ALL_JOINTS = tuple(f"{s}_{j}" for s in _SIDES for j in list(body.ARM_JOINTS) + ["fingers"])


@dataclasses.dataclass(frozen=True)
class TouchConfig:
    spacing_hand: float = 0.007
    spacing_fingers: float = 0.002
    spread_factor: float = 1.5

    def validate(self) -> None:
        check(0.001 <= self.spacing_hand <= 0.03, "spacing_hand", f"must be in [0.001, 0.03] m, got {self.spacing_hand}")
        check(0.001 <= self.spacing_fingers <= 0.03, "spacing_fingers",
              f"must be in [0.001, 0.03] m, got {self.spacing_fingers}")
        # Below one spacing a contact between sensors could reach none of them and its force be lost.
        check(1.0 <= self.spread_factor <= 5, "spread_factor",
              f"must be in [1, 5] sensor spacings, got {self.spread_factor}")


@dataclasses.dataclass(frozen=True)
class RewardConfig:
    """Weights of the intrinsic reward terms (0 switches a term off) and the terms' constants."""

    contact: float = 1.0
    novelty: float = 1.0
    region: float = 1.0
    movement: float = 1.0
    energy: float = 1.0
    joint_limit: float = 1.0
    contact_scale: float = 4.0
    contact_gain: float = 0.05
    region_new: float = 0.3
    region_stale: float = -1.0
    speed_low: float = 1.0
    speed_high: float = 3.0
    movement_penalty: float = -0.5
    energy_coef: float = 0.001
    limit_threshold: float = 0.8
    limit_coef: float = 0.8

    def validate(self) -> None:
        check(0 <= self.speed_low < self.speed_high, "speed_low",
              f"must satisfy 0 <= speed_low < speed_high, got {self.speed_low}, {self.speed_high}")
        check(0 <= self.limit_threshold < 1, "limit_threshold", f"must be in [0, 1), got {self.limit_threshold}")
        check(self.contact_gain > 0, "contact_gain", f"must be > 0, got {self.contact_gain}")

    def weights(self) -> tuple[float, ...]:
        return (self.contact, self.novelty, self.region, self.movement, self.energy, self.joint_limit)


# Physics backends: MJX (JAX, for accelerators) or native C MuJoCo through a callback (for CPUs);
# "auto" picks native when JAX runs on the CPU and MJX otherwise (experiments/env_factory.py).
BACKENDS = ("auto", "mjx", "native")

REWARD_TERMS = ("contact", "novelty", "region", "movement", "energy", "joint_limit")


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    k: int = 10
    episode_length: int = 1000
    qpos_joints: tuple[str, ...] = tuple(f"{s}_{j}" for s in _SIDES for j in _ARM + ("wrist_flexion", "fingers"))
    qvel_joints: tuple[str, ...] = tuple(f"{s}_{j}" for s in _SIDES for j in _ARM + ("wrist_flexion", "fingers"))
    torque_actuators: tuple[str, ...] = tuple(f"{s}_{j}" for s in _SIDES for j in _ARM)
    speed_joints: tuple[str, ...] = tuple(f"{s}_{j}" for s in _SIDES for j in _ARM)
    freeze_speed: float = 1.0
    reset_noise_steps: int = 10
    reset_noise_scale: float = 0.1
    reset_pool_size: int = 256
    reset_pool_seed: int = 0
    physics: PhysicsConfig = PhysicsConfig()
    touch: TouchConfig = TouchConfig()
    reward: RewardConfig = RewardConfig()
    backend: str = "auto"

    def validate(self) -> None:
        check(self.backend in BACKENDS, "backend", f"must be one of {', '.join(BACKENDS)}, got {self.backend!r}")
        check(1 <= self.k <= 40, "k", f"must be an integer in [1, 40] (nearest touch sensors), got {self.k}")
        check(self.episode_length >= 1, "episode_length", f"must be >= 1, got {self.episode_length}")
        for field in ("qpos_joints", "qvel_joints", "speed_joints"):
            names = getattr(self, field)
            check(len(names) >= 1, field, "must name at least one joint")
            bad = [n for n in names if n not in ALL_JOINTS]
            check(not bad, field, f"unknown joint(s) {bad}; allowed: {', '.join(ALL_JOINTS)}")
        bad = [n for n in self.torque_actuators if n not in body.ACTUATED_JOINTS]
        check(not bad, "torque_actuators", f"unknown actuator(s) {bad}; allowed: {', '.join(body.ACTUATED_JOINTS)}")
        check(self.freeze_speed > 0, "freeze_speed", f"must be > 0 rad/s, got {self.freeze_speed}")
        check(0 <= self.reset_noise_steps <= 200, "reset_noise_steps", f"must be in [0, 200], got {self.reset_noise_steps}")
        check(0 <= self.reset_noise_scale <= 1, "reset_noise_scale", f"must be in [0, 1], got {self.reset_noise_scale}")
        check(1 <= self.reset_pool_size <= 4096, "reset_pool_size", f"must be in [1, 4096], got {self.reset_pool_size}")

    @property
    def observation_size(self) -> int:
        return 4 * (self.k + 3) + len(self.qpos_joints) + len(self.qvel_joints) + len(self.torque_actuators)
