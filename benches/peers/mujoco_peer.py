"""MuJoCo peer of `icms bench tick`: the same held-object scene, timed with the same statistic.

    python3 -m venv /tmp/mj && /tmp/mj/bin/pip install mujoco
    /tmp/mj/bin/python benches/peers/mujoco_peer.py --scene fingertips

Prints the scene and the per-batch figures, and on its last line the median microseconds per
1 ms step. Run it in the same minutes as `icms bench tick --scene fingertips --json` and quote
the ratio of the two medians, not absolute times (the machine's speed varies between runs).

The scene (`--scene fingertips`) is the DFS's, read from `fingertips_scene.json` beside this
file (written by `icms bench tick --scene fingertips --describe`; a test in
api/tests/integration/cli_bench.rs keeps the two equal):

- glove10 as MJCF (`glove10_mjcf.py`: the same links, masses, inertias, joint limits, armature
  and damping; the coupled joints as stiff joint equality constraints), its base (forearm)
  fixed where the DFS has it (palm up, rolled 20°), the hand's own weight compensated (the
  DFS's fingers have no weight);
- the ball: the same radius, mass and friction (point contacts with friction, `condim` 3,
  elliptic cones), where the DFS starts it, touching the same four fingertips; only the
  fingertip spheres collide, and only with the ball (the DFS has no other contact geometry);
- the operator's grip: a position actuator per DOF with the DFS operator's stiffness and damping
  and its set posture as target, offset by the feed-forward torque over the stiffness, so the
  actuator's force is the DFS operator's `g(t) τ_ff + K_p (θ_set − θ) − K_d θ̇`, with the same
  slowly swinging grip `g(t)`;
- 1 ms steps (`implicitfast`), `impratio` 10 (MuJoCo's advice for grasps: friction ten times
  stiffer than by default; with the default the ball creeps out of the grip within seconds),
  the ball's contacts with `solref` 0.004 s (the default 0.02 s lets it sink millimetres into
  the fingertips).

Timing: a warm-up (the grasp settles), then `--batches` batches of `--batch-steps` steps, each
one call of `mujoco.rollout.rollout` (the steps run in C with the precomputed controls, no
Python per step; a call of a single step takes about a step's time, so a call's own cost is
well under 1 % of a batch), each batch continuing from the state and warm start the one before
ended in. The printed figure is the median over the batches of the batch's time per step: what
`icms bench tick` reports as `median_ns` (its batches of 100 ticks timed whole). On a shared
machine a batch is either untouched by another process's time slice (a few ms) or slowed by a
whole one; batches much shorter than a slice (100 steps: 1.5-2 ms here, the DFS's 100 ticks
0.3 ms) are mostly untouched, and the median keeps those. After the run the script checks that
the ball is still held (at least three fingertip contacts, moved less than 10 mm in the hand)
and fails otherwise.

`--scene power-grasp` is the DFS's power grasp (`power_grasp_scene.json` beside this file,
written by `icms bench tick --scene power-grasp --describe`): glove10 palm up with whole-hand
contact geometry (the palm box, the phalanx capsules and the fingertip spheres all collide with
the object, `condim` 3, the object's friction), the cylinder where the DFS's grasp settled, the
hand in the posture its fingers came to rest in, the operator's law `g(t) τ_close + K_p (θ_set −
θ) − K_d θ̇` as position actuators as above; the same solver options. After the run it checks
that the palm or a phalanx still touches the cylinder and that it moved less than 10 mm in the
hand.
"""

import argparse
import json
import math
import os
import statistics
import sys
import time

import numpy as np
import mujoco
from mujoco import rollout

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import glove10_mjcf as glove10  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
# Friction's impedance relative to the normal's (MuJoCo's advice for grasps).
IMPRATIO = 10


def f(*v):
    return " ".join(f"{x:.17g}" for x in v)


def joint_values(dofs, q):
    """glove10's DOF values → every MJCF joint's value (the coupled joints follow)."""
    v = dict(zip(dofs, q))
    v["thumb_ip"] = v["thumb_mcp"]
    for finger in ["ring", "little"]:
        v[f"{finger}_mcp"] = v["middle_mcp"]
        v[f"{finger}_pip"] = v["middle_pip"]
    for finger in ["middle", "ring", "little"]:
        v[f"{finger}_dip"] = glove10.DIP_PIP_RATIO * v[f"{finger}_pip"]
    return v


def hand_model(scene, name, object_body, whole_hand=False):
    """The MJCF model named `name`: `object_body` (the object's free body), glove10 (with
    `whole_hand`: its whole-hand contact geometry) on its forearm fixed where the scene has it,
    a position actuator per DOF with the operator's stiffness and damping; and its data in the
    scene's starting posture."""
    dofs = scene["dofs"]
    kp, kd = scene["kp"], scene["kd"]
    actuators = "\n".join(
        f'<position name="{d}" joint="{d}" kp="{kp[i]:.17g}" kv="{kd[i]:.17g}" ctrllimited="false"/>'
        for i, d in enumerate(dofs)
    )
    xml = f"""<mujoco model="{name}">
  <compiler angle="radian"/>
  <option timestep="{scene['dt']}" gravity="{f(*scene['gravity'])}" cone="elliptic"
          impratio="{IMPRATIO}" integrator="implicitfast"/>
  <worldbody>
    {object_body}
    <body name="forearm" mocap="true" pos="{f(*scene['base_position'])}" quat="{f(*scene['base_quaternion'])}">
      {glove10.glove10_body(["thumb", "index", "middle", "ring", "little"], whole_hand=whole_hand)}
    </body>
  </worldbody>
  <equality>
    {glove10.glove10_equalities()}
  </equality>
  <actuator>
    {actuators}
  </actuator>
</mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    for name, value in joint_values(dofs, scene["q"]).items():
        data.qpos[model.joint(name).qposadr[0]] = value
    mujoco.mj_forward(model, data)
    return model, data


def grip_controls(scene):
    """The operator's grip as the actuators' targets: `controls(step0, nstep)` for steps
    step0.. is θ_set + g(t) τ_ff / K_p."""
    q = np.array(scene["q"])
    tau = np.array(scene["tau_ff"])
    kp = np.array(scene["kp"])

    def controls(step0, nstep):
        t = (step0 + np.arange(nstep)) * scene["dt"]
        grip = 1.0 + scene["grip_swing"] * np.sin(2.0 * math.pi * t / scene["grip_period_s"])
        return q[None, :] + grip[:, None] * (tau / kp)[None, :]

    return controls


def fingertips_model(scene):
    ball = f"""<body name="object" pos="{f(*scene['ball_position'])}">
      <freejoint/>
      <geom name="object" type="sphere" size="{scene['ball_radius']:.17g}" mass="{scene['ball_mass']:.17g}"
            friction="{scene['ball_mu']:.17g} 0 0" condim="3" contype="0" conaffinity="1"
            solref="0.004 1"/>
    </body>"""
    model, data = hand_model(scene, "glove10_fingertips", ball)
    # The MJCF hand is glove10: at the DFS's start the same fingertips touch the ball.
    centre = data.body("object").xpos
    for tip in scene["contact_tips"]:
        geom = model.geom(f"tip_{tip}").id
        gap = np.linalg.norm(data.geom_xpos[geom] - centre) - scene["ball_radius"] - model.geom_size[geom][0]
        if abs(gap) >= 1e-6:
            sys.exit(f"mujoco_peer.py: fingertip {tip} starts {gap * 1e3:.3f} mm from the ball, not on it")
    return model, data, grip_controls(scene)


def power_grasp_model(scene):
    mu = scene["cylinder_mu"]
    cylinder = f"""<body name="object" pos="{f(*scene['cylinder_position'])}" quat="{f(*scene['cylinder_quaternion'])}">
      <freejoint/>
      <geom name="object" type="cylinder" size="{scene['cylinder_radius']:.17g} {scene['cylinder_half_height']:.17g}"
            mass="{scene['cylinder_mass']:.17g}" friction="{mu:.17g} 0 0" condim="3" contype="0"
            conaffinity="1" solref="0.004 1"/>
    </body>"""
    model, data = hand_model(scene, "glove10_power_grasp", cylinder, whole_hand=True)
    # The MJCF hand is glove10's whole-hand geometry: at the start the DFS's pressing contacts
    # touch the cylinder here too (within 1 mm: the DFS's contacts are springs pressed in).
    touching = set()
    obj = model.geom("object").id
    for i in range(data.ncon):
        c = data.contact[i]
        if obj in (c.geom[0], c.geom[1]) and c.dist <= 1e-3:
            other = c.geom[1] if c.geom[0] == obj else c.geom[0]
            touching.add(model.geom(other).name)
    missing = [c for c in scene["contacts"] if c not in touching]
    if missing:
        sys.exit(f"mujoco_peer.py: power-grasp: {missing} do not touch the cylinder at the start")
    return model, data, grip_controls(scene)


def held(model, data, start_in_hand):
    """(the hand's contacts on the object, distance the object moved in the hand (m))."""
    obj = model.geom("object").id
    touching = sum(
        1
        for i in range(data.ncon)
        if obj in (data.contact[i].geom[0], data.contact[i].geom[1]) and data.contact[i].dist <= 0
    )
    return touching, float(np.linalg.norm(in_hand(model, data) - start_in_hand))


def in_hand(model, data):
    base = data.body("forearm")
    return base.xmat.reshape(3, 3).T @ (data.body("object").xpos - base.xpos)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scene", choices=["fingertips", "power-grasp"], default="fingertips")
    p.add_argument("--scene-file", default=os.path.join(HERE, "fingertips_scene.json"))
    p.add_argument("--warmup", type=int, default=2000, help="steps before timing (default 2000)")
    p.add_argument("--batches", type=int, default=1000, help="timed batches (default 1000)")
    p.add_argument(
        "--batch-steps", type=int, default=100, help="steps per batch (default 100, as the DFS's)"
    )
    a = p.parse_args()

    if a.scene == "fingertips":
        with open(a.scene_file) as fh:
            scene = json.load(fh)
        model, data, controls = fingertips_model(scene)
        min_contacts = len(scene["contact_tips"]) - 1
    else:
        path = a.scene_file
        if path == os.path.join(HERE, "fingertips_scene.json"):
            path = os.path.join(HERE, "power_grasp_scene.json")
        with open(path) as fh:
            scene = json.load(fh)
        model, data, controls = power_grasp_model(scene)
        min_contacts = 1

    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    nstate = mujoco.mj_stateSize(model, spec)
    state = np.empty(nstate)
    mujoco.mj_getState(model, data, state, spec)
    start = in_hand(model, data)
    warmstart = data.qacc_warmstart.copy()
    ctrl_spec = mujoco.mjtState.mjSTATE_CTRL

    def run(step0, nstep, out):
        """Steps nstep from `state` in C; leaves `state`, `warmstart` at the end."""
        nonlocal state, warmstart
        ctrl = controls(step0, nstep)[None, :, :]
        rollout.rollout(
            [model], [data], state[None, :], ctrl, control_spec=ctrl_spec, skip_checks=True,
            nstep=nstep, initial_warmstart=warmstart[None, :], state=out,
        )
        state = out[0, -1].copy()
        warmstart = data.qacc_warmstart.copy()

    step = 0
    if a.warmup:
        run(step, a.warmup, np.empty((1, a.warmup, nstate)))
        step += a.warmup
    out = np.empty((1, a.batch_steps, nstate))
    per_step_us = []
    for _ in range(a.batches):
        ctrl_ready = controls(step, a.batch_steps)  # made before the clock starts
        t0 = time.perf_counter()
        rollout.rollout(
            [model], [data], state[None, :], ctrl_ready[None, :, :], control_spec=ctrl_spec,
            skip_checks=True, nstep=a.batch_steps, initial_warmstart=warmstart[None, :], state=out,
        )
        per_step_us.append((time.perf_counter() - t0) / a.batch_steps * 1e6)
        state = out[0, -1].copy()
        warmstart = data.qacc_warmstart.copy()
        step += a.batch_steps

    mujoco.mj_setState(model, data, state, spec)
    mujoco.mj_forward(model, data)
    contacts, shift = held(model, data, start)
    print(
        f"MuJoCo {mujoco.__version__}, scene {a.scene}: {model.nv} DOFs, {model.neq} equality constraints, "
        f"{contacts} contacts at the end, object moved {shift * 1e3:.2f} mm in the hand; "
        f"{a.batches} batches of {a.batch_steps} steps after {a.warmup}: per step "
        f"min {min(per_step_us):.3f} us, mean {statistics.fmean(per_step_us):.3f} us"
    )
    if contacts < min_contacts or shift >= 0.010:
        sys.exit(
            f"mujoco_peer.py: the object is no longer held ({contacts} contacts, moved "
            f"{shift * 1e3:.1f} mm in the hand): the timing is not of a held-object scene"
        )
    print(f"{statistics.median(per_step_us):.3f}")


if __name__ == "__main__":
    main()
