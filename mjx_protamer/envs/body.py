"""Our infant body model, written as MJCF from the facts of the reference (MIMo v1, mitten hands).

The infant lies on its back on the floor. World frame: x runs from the feet to the head, y to the
infant's left, z up from the floor. Trunk, head and legs are welded to the world (the paper locks them);
each arm is shoulder (3 hinges) -> upper arm -> elbow -> lower arm -> wrist (3 hinges) -> palm ->
a passive mitten-finger hinge. 14 position actuators in the reference's action order.

Only spheres, capsules and a plane, so every pair is one MJX can collide cheaply. Collisions are a
small, deliberate set of explicit <pair>s (all geoms have contype = conaffinity = 0): hand and finger
geoms against the body geoms, the other arm and the other hand; arms and hands against the floor.
MJX has no dynamic broadphase, so every candidate pair costs time whether or not it touches.

Gains: the reference's position servos (kp 1 N m/rad, no damping) miss held poses by up to 0.57 rad.
Ours use kp sized against gravity at full arm extension, a velocity gain near critical damping and
joint armature (reflected motor inertia) so the explicit Euler step at 5 ms stays stable; torques are
clipped at the reference's maximum voluntary torques. Measured tracking error: docs/environment.md.
"""

from __future__ import annotations

import dataclasses
import math

# Region names, in the order of the region mask (the spec's 8), then the extended set.
REGIONS: tuple[str, ...] = (
    "hip", "lower_body", "upper_body", "head",
    "left_upper_arm", "right_upper_arm", "left_lower_arm", "right_lower_arm",
)
EXTENDED_REGIONS: tuple[str, ...] = ("left_hand", "right_hand", "left_leg", "right_leg")

# The 14 actuators in the reference's action order.
ACTUATED_JOINTS: tuple[str, ...] = (
    "right_shoulder_horizontal", "right_shoulder_ad_ab", "right_shoulder_rotation", "right_elbow",
    "left_shoulder_horizontal", "left_shoulder_ad_ab", "left_shoulder_rotation", "left_elbow",
    "right_wrist_rotation", "right_wrist_flexion", "right_wrist_ulnar",
    "left_wrist_rotation", "left_wrist_flexion", "left_wrist_ulnar",
)

# Hand geoms carrying touch sensors, in the order of the observation's touch blocks.
HAND_GEOMS: tuple[str, ...] = ("left_palm", "left_fingers", "right_palm", "right_fingers")


@dataclasses.dataclass(frozen=True)
class JointSpec:
    axis: tuple[float, float, float]
    range_deg: tuple[float, float]
    max_torque: float  # N m (reference's maximum voluntary torque)
    kp: float  # N m / rad
    kv: float  # N m s / rad
    armature: float  # kg m^2


# Axes are written for the LEFT arm, which points along -x at zero angles; the right arm mirrors
# them through the x-z plane (y -> -y). Ranges are the reference's (degrees).
ARM_JOINTS: dict[str, JointSpec] = {
    # raises the arm from the floor toward the ceiling and over the head
    "shoulder_horizontal": JointSpec((0, 1, 0), (-28, 118), 1.8, 12.0, 0.8, 0.010),
    # moves the arm away from the trunk (positive) or across it (negative)
    "shoulder_ad_ab": JointSpec((0, 0, -1), (-84, 183), 4.0, 12.0, 0.8, 0.010),
    "shoulder_rotation": JointSpec((1, 0, 0), (-99, 67), 2.5, 8.0, 0.4, 0.004),
    # negative flexes the forearm up and back toward the shoulder
    "elbow": JointSpec((0, -1, 0), (-146, 5), 3.6, 10.0, 0.4, 0.004),
    "wrist_rotation": JointSpec((1, 0, 0), (-90, 90), 0.7, 2.0, 0.08, 0.0015),
    "wrist_flexion": JointSpec((0, 1, 0), (-92, 86), 1.24, 2.0, 0.08, 0.0015),
    "wrist_ulnar": JointSpec((0, 0, 1), (-53, 48), 0.95, 2.0, 0.08, 0.0015),
}
FINGER_RANGE_DEG = (-160.0, 8.0)
FINGER_REST_DEG = -40.0

# Segment geometry (m) and masses (kg) for one arm.
UPPER_ARM_LEN, UPPER_ARM_R, UPPER_ARM_MASS = 0.105, 0.024, 0.25
LOWER_ARM_LEN, LOWER_ARM_R, LOWER_ARM_MASS = 0.095, 0.021, 0.15
PALM_R, PALM_MASS = 0.024, 0.08
FINGER_HALF, FINGER_R, FINGER_MASS = 0.018, 0.012, 0.03
SHOULDER = (0.205, 0.098, 0.075)  # left shoulder position; the right one mirrors y

# Rest pose (degrees) the env settles into before each episode.
REST_POSE_DEG: dict[str, float] = {
    "shoulder_horizontal": 10.0, "shoulder_ad_ab": 10.0, "shoulder_rotation": 0.0, "elbow": -30.0,
    "wrist_rotation": 0.0, "wrist_flexion": 0.0, "wrist_ulnar": 0.0,
}


@dataclasses.dataclass(frozen=True)
class PhysicsConfig:
    """Simulator settings. The defaults are the fast MJX settings; `reference()` is MuJoCo's own."""

    timestep: float = 0.005  # s per physics step, also the control period (200 Hz: one action per step)
    solver: str = "Newton"  # MuJoCo's constraint solver: Newton or CG
    iterations: int = 2  # solver iterations per step (reference(): 100; fewer make a step faster)
    ls_iterations: int = 4  # line-search iterations per solver iteration (reference(): 50)
    self_condim: int = 1  # hand/body contacts: frictionless skin (1) or with friction (3)
    floor_condim: int = 3  # the floor's contacts: 3 with friction, 1 frictionless
    # implicit joint damping in the Euler integrator (reference(): on)
    eulerdamp: bool = False
    max_contact_points: int = 8  # per condim group, MJX keeps the deepest N (-1: all)

    @staticmethod
    def reference() -> "PhysicsConfig":
        return PhysicsConfig(iterations=100, ls_iterations=50, self_condim=3, eulerdamp=True,
                             max_contact_points=-1)

    def validate(self) -> None:
        from mjx_protamer.config import check

        check(0 < self.timestep <= 0.02, "timestep", f"must be in (0, 0.02] s, got {self.timestep}")
        check(self.solver in ("Newton", "CG"), "solver", f"must be 'Newton' or 'CG', got {self.solver!r}")
        check(1 <= self.iterations <= 100, "iterations", f"must be in [1, 100], got {self.iterations}")
        check(1 <= self.ls_iterations <= 100, "ls_iterations", f"must be in [1, 100], got {self.ls_iterations}")
        check(self.self_condim in (1, 3), "self_condim", f"must be 1 or 3, got {self.self_condim}")
        check(self.floor_condim in (1, 3), "floor_condim", f"must be 1 or 3, got {self.floor_condim}")
        check(self.max_contact_points == -1 or self.max_contact_points >= 1, "max_contact_points",
              f"must be -1 (all) or >= 1, got {self.max_contact_points}")


def _fmt(v) -> str:
    return " ".join(f"{x:.6g}" for x in v)


def _mirror(axis: tuple[float, float, float], side: str) -> tuple[float, float, float]:
    # Mirroring through the x-z plane flips y components of positions; for rotation axes
    # (pseudo-vectors) it flips the x and z components instead, so motions mirror.
    if side == "left":
        return axis
    return (-axis[0], axis[1], -axis[2])


def _arm_xml(side: str) -> str:
    sy = 1.0 if side == "left" else -1.0
    other = "right" if side == "left" else "left"
    sx, syy, sz = SHOULDER
    j = {name: spec for name, spec in ARM_JOINTS.items()}

    def hinge(name: str) -> str:
        spec = j[name]
        return (f'<joint name="{side}_{name}" type="hinge" axis="{_fmt(_mirror(spec.axis, side))}" '
                f'range="{_fmt(spec.range_deg)}" armature="{spec.armature}" damping="0.005" '
                f'stiffness="0.001"/>')

    del other
    return f"""
    <body name="{side}_upper_arm" pos="{_fmt((sx, sy * syy, sz))}">
      {hinge("shoulder_horizontal")}
      {hinge("shoulder_ad_ab")}
      {hinge("shoulder_rotation")}
      <geom name="{side}_upper_arm" type="capsule" fromto="-0.012 0 0 {-UPPER_ARM_LEN:.4f} 0 0"
            size="{UPPER_ARM_R}" mass="{UPPER_ARM_MASS}" rgba=".95 .8 .7 1"/>
      <body name="{side}_lower_arm" pos="{-UPPER_ARM_LEN:.4f} 0 0">
        {hinge("elbow")}
        <geom name="{side}_lower_arm" type="capsule" fromto="-0.01 0 0 {-LOWER_ARM_LEN:.4f} 0 0"
              size="{LOWER_ARM_R}" mass="{LOWER_ARM_MASS}" rgba=".95 .8 .7 1"/>
        <body name="{side}_hand" pos="{-LOWER_ARM_LEN - 0.016:.4f} 0 0">
          {hinge("wrist_rotation")}
          {hinge("wrist_flexion")}
          {hinge("wrist_ulnar")}
          <geom name="{side}_palm" type="sphere" pos="-0.01 0 0" size="{PALM_R}" mass="{PALM_MASS}"
                rgba=".95 .75 .65 1"/>
          <body name="{side}_fingers" pos="-0.03 0 0">
            <joint name="{side}_fingers" type="hinge" axis="{_fmt(_mirror((0, 1, 0), side))}"
                   range="{_fmt(FINGER_RANGE_DEG)}" springref="{FINGER_REST_DEG}" stiffness="0.02"
                   damping="0.004" armature="0.0008"/>
            <geom name="{side}_fingers" type="capsule" fromto="-0.004 0 0 {-2 * FINGER_HALF - 0.004:.4f} 0 0"
                  size="{FINGER_R}" mass="{FINGER_MASS}" rgba=".95 .75 .65 1"/>
          </body>
        </body>
      </body>
    </body>"""


def _pairs(opts: PhysicsConfig) -> list[str]:
    body = ["hip", "lower_body", "upper_body", "head", "left_upper_leg", "right_upper_leg"]
    pairs = []
    for side, other in (("left", "right"), ("right", "left")):
        targets = body + [f"{side}_upper_arm", f"{other}_upper_arm", f"{other}_lower_arm"]
        for hand in (f"{side}_palm", f"{side}_fingers"):
            for t in targets:
                pairs.append((hand, t, opts.self_condim))
    for a in ("left_palm", "left_fingers"):
        for b in ("right_palm", "right_fingers"):
            pairs.append((a, b, opts.self_condim))
    for side in ("left", "right"):
        for part in ("upper_arm", "lower_arm", "palm", "fingers"):
            pairs.append(("floor", f"{side}_{part}", opts.floor_condim))
    return [f'<pair geom1="{a}" geom2="{b}" condim="{c}"/>' for a, b, c in pairs]


def actuator_xml() -> str:
    lines = []
    for name in ACTUATED_JOINTS:
        side, joint = name.split("_", 1)
        spec = ARM_JOINTS[joint]
        lo, hi = (math.radians(x) for x in spec.range_deg)
        lines.append(
            f'<position name="{name}" joint="{name}" kp="{spec.kp}" kv="{spec.kv}" '
            f'ctrlrange="{lo:.6f} {hi:.6f}" forcerange="{-spec.max_torque} {spec.max_torque}"/>'
        )
    return "\n    ".join(lines)


def infant_xml(opts: PhysicsConfig | None = None) -> str:
    """The MJCF of the infant scene with the given simulator settings."""
    opts = opts or PhysicsConfig()
    flags = [] if opts.eulerdamp else ['eulerdamp="disable"']
    numeric = (f'<custom><numeric name="max_contact_points" data="{opts.max_contact_points}"/></custom>'
               if opts.max_contact_points > 0 else "")
    return f"""<mujoco model="mjx_protamer_infant">
  <compiler angle="degree" autolimits="true"/>
  <option timestep="{opts.timestep}" integrator="Euler" solver="{opts.solver}"
          iterations="{opts.iterations}" ls_iterations="{opts.ls_iterations}" cone="pyramidal">
    <flag {" ".join(flags)}/>
  </option>
  {numeric}
  <default>
    <geom contype="0" conaffinity="0" condim="3" friction="0.9 0.005 0.0001" solref="0.01 1"/>
  </default>
  <worldbody>
    <light pos="0 0 1.5" dir="0 0 -1"/>
    <geom name="floor" type="plane" size="1 1 0.05" rgba=".8 .85 .9 1"/>
    <!-- trunk, head and legs are welded to the world: the paper locks them -->
    <body name="hip" pos="0 0 0.055">
      <geom name="hip" type="capsule" fromto="0 -0.045 0 0 0.045 0" size="0.055" mass="1.6"/>
    </body>
    <body name="lower_body" pos="0.085 0 0.058">
      <geom name="lower_body" type="capsule" fromto="0 -0.04 0 0 0.04 0" size="0.058" mass="1.5"/>
    </body>
    <body name="upper_body" pos="0.175 0 0.062">
      <geom name="upper_body" type="capsule" fromto="0 -0.045 0 0 0.045 0" size="0.062" mass="1.9"/>
    </body>
    <body name="head" pos="0.315 0 0.0735">
      <geom name="head" type="sphere" size="0.0735" mass="2.0"/>
    </body>
    <body name="left_upper_leg" pos="-0.02 0.045 0.045">
      <geom name="left_upper_leg" type="capsule" fromto="0 0 0 -0.13 0.01 -0.005" size="0.042" mass="0.55"/>
      <geom name="left_lower_leg" type="capsule" fromto="-0.14 0.01 -0.005 -0.25 0.015 -0.01" size="0.034" mass="0.35"/>
      <geom name="left_foot" type="capsule" fromto="-0.27 0.015 -0.01 -0.27 0.015 0.04" size="0.025" mass="0.12"/>
    </body>
    <body name="right_upper_leg" pos="-0.02 -0.045 0.045">
      <geom name="right_upper_leg" type="capsule" fromto="0 0 0 -0.13 -0.01 -0.005" size="0.042" mass="0.55"/>
      <geom name="right_lower_leg" type="capsule" fromto="-0.14 -0.01 -0.005 -0.25 -0.015 -0.01" size="0.034" mass="0.35"/>
      <geom name="right_foot" type="capsule" fromto="-0.27 -0.015 -0.01 -0.27 -0.015 0.04" size="0.025" mass="0.12"/>
    </body>
    {_arm_xml("left")}
    {_arm_xml("right")}
  </worldbody>
  <contact>
    {chr(10).join("    " + p for p in _pairs(opts))}
  </contact>
  <actuator>
    {actuator_xml()}
  </actuator>
</mujoco>
"""


# Geom -> region tables, by geom name.
GEOM_REGION: dict[str, str] = {
    "hip": "hip", "lower_body": "lower_body", "upper_body": "upper_body", "head": "head",
    "left_upper_arm": "left_upper_arm", "right_upper_arm": "right_upper_arm",
    "left_lower_arm": "left_lower_arm", "right_lower_arm": "right_lower_arm",
    "left_palm": "left_hand", "left_fingers": "left_hand",
    "right_palm": "right_hand", "right_fingers": "right_hand",
    "left_upper_leg": "left_leg", "right_upper_leg": "right_leg",
    "left_lower_leg": "left_leg", "right_lower_leg": "right_leg",
    "left_foot": "left_leg", "right_foot": "right_leg",
}
# A hand touching its own lower arm is not a self-contact (the spec's rule).
OWN_EXCLUDED_REGION = {"left": "left_lower_arm", "right": "right_lower_arm"}
