"""Configuration of the self-touch environment: every knob in one place (validated)."""

from __future__ import annotations

import dataclasses

from mjx_protamer.config import check, check_seed
from mjx_protamer.envs import body
from mjx_protamer.envs.body import PhysicsConfig

_SIDES = ("left", "right")
_ARM = ("shoulder_horizontal", "shoulder_ad_ab", "shoulder_rotation", "elbow")
ALL_JOINTS = tuple(f"{s}_{j}" for s in _SIDES for j in list(body.ARM_JOINTS) + ["fingers"])


@dataclasses.dataclass(frozen=True)
class TouchConfig:
    spacing_hand: float = 0.007  # m between the palm's sensor points (7 mm: 148 sensors, as in the reference)
    spacing_fingers: float = 0.002  # m between the finger capsule's sensor points (2 mm: 1,174 sensors)
    spread_factor: float = 1.5  # a contact's force is spread over the sensors within this many spacings (1.5: about 7)

    def validate(self) -> None:
        check(0.001 <= self.spacing_hand <= 0.03, "spacing_hand", f"must be in [0.001, 0.03] m, got {self.spacing_hand}")
        check(0.001 <= self.spacing_fingers <= 0.03, "spacing_fingers",
              f"must be in [0.001, 0.03] m, got {self.spacing_fingers}")
        # Below one spacing a contact between sensors could reach none of them and its force be lost.
        check(1.0 <= self.spread_factor <= 5, "spread_factor",
              f"must be in [1, 5] sensor spacings, got {self.spread_factor}")


@dataclasses.dataclass(frozen=True)
class RewardConfig:
    """Weights of the intrinsic reward terms (0 switches a term off) and the terms' constants.

    The defaults are this project's infant preset; `reward: paper` in a config selects `RewardConfig.paper()`,
    the reference reward of the spec, kept for reproduction. What differs and why (docs/experiments.md):
    contact pays for touching (saturates near 1 N) rather than for pressing (20 N); novelty reads the touch
    features squashed by `novelty_force_scale` and clipped, so force chatter cannot outweigh touching.
    """

    contact: float = 1.0  # weight of the contact term (docs/environment.md, "Reward", has every term's formula)
    novelty: float = 1.0  # weight of the novelty term: the change of the touch features since the last step
    region: float = 1.0  # weight of the region term: region_new when a region is newly touched, else region_stale
    movement: float = 1.0  # weight of the movement-band term (movement_penalty outside [speed_low, speed_high])
    energy: float = 1.0  # weight of the energy term: -energy_coef x the squared actuator forces
    joint_limit: float = 1.0  # weight of the joint-limit term: -limit_coef x the actions past limit_threshold
    contact_scale: float = 1.0  # the contact term is contact_scale x tanh(contact_gain x sum |touch features|)
    # 1/N: 2 makes a 1 N touch earn 0.96 of contact_scale (the paper preset's 0.05 is still rising at 20 N)
    contact_gain: float = 2.0
    novelty_force_scale: float = 1.0  # N; features enter novelty as tanh(x / scale); 0: raw features (paper)
    novelty_clip: float = 1.0  # novelty is at most this; 0: unclipped (paper)
    region_new: float = 0.3  # the region term on a step whose touched regions are not a subset of the last step's
    region_stale: float = -1.0  # the region term on every other step
    speed_low: float = 1.0  # rad/s: the movement band's lower end (arm joint-speed norm, env.speed_joints)
    speed_high: float = 3.0  # rad/s: the movement band's upper end
    # the movement term outside the band (below speed_low or above speed_high), 0 inside it
    movement_penalty: float = -0.5
    energy_coef: float = 0.001  # per N^2 of actuator force, summed over the actuators
    limit_threshold: float = 0.8  # |action| past this (of the servo range, 1) is penalised: near the joint limits
    limit_coef: float = 0.8  # per unit of |action| past limit_threshold, summed over the action dimensions
    # Pays sum over touched regions of (1 - familiarity): a region is worth touching while it is
    # unfamiliar. Zero unless the env keeps a familiarity trace (EnvConfig.habituation_s > 0).
    habituation: float = 1.0

    PRESETS = ("infant", "paper")

    @staticmethod
    def preset(name: str) -> "RewardConfig":
        if name == "infant":
            return RewardConfig()
        if name == "paper":
            return RewardConfig(contact_scale=4.0, contact_gain=0.05, novelty_force_scale=0.0, novelty_clip=0.0,
                            habituation=0.0)
        from mjx_protamer.config import ConfigError
        raise ConfigError(f"config field 'reward': unknown preset {name!r}; presets: {', '.join(RewardConfig.PRESETS)}")

    def validate(self) -> None:
        check(0 <= self.speed_low < self.speed_high, "speed_low",
              f"must satisfy 0 <= speed_low < speed_high, got {self.speed_low}, {self.speed_high}")
        check(0 <= self.limit_threshold < 1, "limit_threshold", f"must be in [0, 1), got {self.limit_threshold}")
        check(self.contact_gain > 0, "contact_gain", f"must be > 0, got {self.contact_gain}")
        check(self.novelty_force_scale >= 0, "novelty_force_scale",
              f"must be >= 0 N (0: raw features), got {self.novelty_force_scale}")
        check(self.novelty_clip >= 0, "novelty_clip", f"must be >= 0 (0: no clip), got {self.novelty_clip}")

    def weights(self) -> tuple[float, ...]:
        return (self.contact, self.novelty, self.region, self.movement, self.energy, self.joint_limit,
                self.habituation)


# Physics backends: MJX (JAX, for accelerators) or native C MuJoCo through a callback (for CPUs);
# "auto" picks native when JAX runs on the CPU and MJX otherwise (experiments/env_factory.py).
BACKENDS = ("auto", "mjx", "native")

REWARD_TERMS = ("contact", "novelty", "region", "movement", "energy", "joint_limit", "habituation")


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    # touch sensors read per hand part: the k nearest the contact point (observation 4 x (k + 3) touch dims)
    k: int = 10
    episode_length: int = 1000  # env steps per episode (5 s at 200 Hz); train.episode_length must equal it
    # joints whose angles enter the observation
    qpos_joints: tuple[str, ...] = tuple(f"{s}_{j}" for s in _SIDES for j in _ARM + ("wrist_flexion", "fingers"))
    # joints whose speeds enter the observation
    qvel_joints: tuple[str, ...] = tuple(f"{s}_{j}" for s in _SIDES for j in _ARM + ("wrist_flexion", "fingers"))
    # actuators whose forces enter the observation
    torque_actuators: tuple[str, ...] = tuple(f"{s}_{j}" for s in _SIDES for j in _ARM)
    # joints whose speed norm is the arm speed: the movement band's and the freeze metric's
    speed_joints: tuple[str, ...] = tuple(f"{s}_{j}" for s in _SIDES for j in _ARM)
    # rad/s: a step with the arm speed below this counts as frozen (the freeze_ratio metric, teachers)
    freeze_speed: float = 1.0
    # Time constant (s) of the low-pass between the action and the servo targets (model.next_ctrl); 0 is
    # the paper's env, where targets jump to each 5 ms action. See docs/experiments.md for why 0.1 s.
    action_filter_s: float = 0.1
    # Frequency (Hz) of a phase signal [sin, cos](2 pi f t) appended to the observation; 0 keeps the paper's
    # 84 dims. Infants' spontaneous "general movements" are rhythmic (central pattern generators, as in
    # Kuniyoshi & Sangawa's fetal self-touch models); a deterministic policy with no clock can only settle
    # into a fixed pose once its exploration noise is off, one with a clock can keep moving.
    oscillator_hz: float = 1.0
    # Habituation to one's own touch: a familiarity trace per region (8), rising towards 1 with time
    # constant `habituation_s` while the region is touched and decaying with `recovery_s` while it is not.
    # The reward's `habituation` term pays for touching unfamiliar regions, and the trace is appended to
    # the observation so the critic can see what it pays for. Infants habituate to a repeated touch and
    # recover from it (docs/experiments.md); the spec's region term pays any onset, so one region
    # tapped or pressed forever earns as much as a tour of the body. 0 switches it off (the paper's
    # obs; run_loader reads a saved run that predates the field as 0).
    habituation_s: float = 0.25
    # s: time constant of the familiarity's decay while a region is not touched (see habituation_s)
    recovery_s: float = 10.0
    # each start state of the reset pool is the settled pose after this many random servo targets (200 Hz steps;
    # envs/model.py says why a pool)
    reset_noise_steps: int = 10
    # std of those targets around the rest pose, as a fraction of each servo's half range
    reset_noise_scale: float = 0.1
    reset_pool_size: int = 256  # start states computed once, natively, when the model is built; a reset draws one
    reset_pool_seed: int = 0  # seed of the NumPy generator that makes the reset pool
    physics: PhysicsConfig = PhysicsConfig()
    touch: TouchConfig = TouchConfig()
    reward: RewardConfig = RewardConfig()
    backend: str = "auto"  # physics: auto, mjx or native (BACKENDS above: auto is native when JAX runs on the CPU)

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
        check(0 <= self.action_filter_s <= 2, "action_filter_s",
              f"must be in [0, 2] s (0: no filter), got {self.action_filter_s}")
        check(0 <= self.oscillator_hz <= 20, "oscillator_hz", f"must be in [0, 20] Hz (0: off), got {self.oscillator_hz}")
        check(0 <= self.habituation_s <= 60, "habituation_s",
              f"must be in [0, 60] s (0: no habituation), got {self.habituation_s}")
        check(0 < self.recovery_s <= 600, "recovery_s", f"must be in (0, 600] s, got {self.recovery_s}")
        check(self.freeze_speed > 0, "freeze_speed", f"must be > 0 rad/s, got {self.freeze_speed}")
        check(0 <= self.reset_noise_steps <= 200, "reset_noise_steps", f"must be in [0, 200], got {self.reset_noise_steps}")
        check_seed(self.reset_pool_seed, "reset_pool_seed")
        check(0 <= self.reset_noise_scale <= 1, "reset_noise_scale", f"must be in [0, 1], got {self.reset_noise_scale}")
        check(1 <= self.reset_pool_size <= 4096, "reset_pool_size", f"must be in [1, 4096], got {self.reset_pool_size}")

    @property
    def action_smoothing(self) -> float:
        """exp(-dt / action_filter_s): the weight of the previous servo target in model.next_ctrl."""
        import math
        if self.action_filter_s == 0:
            return 0.0
        return math.exp(-self.physics.timestep / self.action_filter_s)

    @property
    def observation_size(self) -> int:
        return (4 * (self.k + 3) + len(self.qpos_joints) + len(self.qvel_joints) + len(self.torque_actuators)
                + (2 if self.oscillator_hz > 0 else 0) + (len(body.REGIONS) if self.habituation_s > 0 else 0))

    def familiarity_rates(self) -> tuple[float, float]:
        """Per-step retention of unfamiliarity while touched and of familiarity while not (reward.habituate)."""
        import math
        dt = self.physics.timestep
        return math.exp(-dt / self.habituation_s), math.exp(-dt / self.recovery_s)
