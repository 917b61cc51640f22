"""glove10 (dfs-core/src/hand/glove10.rs) as MuJoCo MJCF, built from the same constants.

Frames, lengths, radii, masses and inertias are those of `HandModel::glove10()`: segment
lengths are Buchholz et al.'s ratios of the 0.19 m hand length, segments are uniform cylinders
and the palm a uniform box of hand tissue (1160 kg/m^3), every DOF has the glove's armature
(1e-5 kg m^2) and damping (0.02 N m s/rad, `DfsParams::joint_damping`). The coupled joints of
glove10 (ring and little MCP/PIP copy the middle finger's, every coupled DIP follows its PIP at
2/3, the thumb IP follows its MCP) are joint equality constraints here (MuJoCo has no mimic
joints), stiff ones (`solref` 0.002 s: with MuJoCo's default 0.02 s the coupled joints give
way under a held ball's weight). MJCF angles are degrees unless `<compiler angle="radian"/>`:
the models using these bodies must say radian. The fingertip spheres collide with the object;
with `whole_hand` the palm box, the eminences and the phalanx capsules do too: glove10's
whole-hand contact geometry (glove10.rs `add_contact_geometry`: the palm box, the thenar and
hypothenar eminence boxes beside it, a capsule along each phalanx with its radius, a distal one
stopping a fingertip diameter short of the finger's end). Without it they
are visual only, as for the `fingertips` scene, where only fingertips touch in the DFS.
"""

import math

HAND_LENGTH = 0.19
HAND_DENSITY = 1160.0
ARMATURE = 1e-5
JOINT_DAMPING = 0.02

# name, MCP in the palm frame, length ratios, segment radii, tip radius (glove10.rs FINGERS)
FINGERS = [
    ("index", (0.374 * HAND_LENGTH, 0.026, 0.0), (0.265, 0.143, 0.097), (0.0100, 0.0090, 0.0080), 0.009),
    ("middle", (0.373 * HAND_LENGTH, 0.006, 0.0), (0.277, 0.170, 0.108), (0.0105, 0.0095, 0.0085), 0.009),
    ("ring", (0.336 * HAND_LENGTH, -0.013, 0.0), (0.259, 0.165, 0.107), (0.0100, 0.0090, 0.0080), 0.0085),
    ("little", (0.295 * HAND_LENGTH, -0.030, 0.0), (0.206, 0.117, 0.094), (0.0090, 0.0080, 0.0070), 0.008),
]
THUMB_CMC_IN_PALM = (0.022, 0.034, -0.012)
THUMB_REST_PITCH = 0.52
THUMB_RATIOS = (0.251, 0.196, 0.158)
THUMB_RADII = (0.0110, 0.0105, 0.0095)
THUMB_TIP_RADIUS = 0.010
PALM_BOX = (0.075, 0.085, 0.030)
# The thenar and hypothenar eminences (glove10.rs EMINENCE_BOX, EMINENCE_RISE): contact boxes
# on the palm's radial and ulnar sides from the wrist, standing proud of its grasping face.
EMINENCE_BOX = (0.03, 0.029, 0.022)
EMINENCE_RISE = 0.0085
FINGER_LIMITS = [(-0.35, 1.57), (0.0, 1.75), (0.0, 1.40)]
DIP_PIP_RATIO = 2.0 / 3.0

# The ten DOFs in glove10's order, with their limits and torque limits (N m).
DOFS = [
    ("wrist_roll", (-1.4, 1.4), 2.0),
    ("wrist_pitch", (-1.2, 1.4), 5.0),
    ("wrist_yaw", (-0.52, 0.35), 4.0),
    ("index_mcp", FINGER_LIMITS[0], 1.0),
    ("index_pip", FINGER_LIMITS[1], 0.6),
    ("index_dip", FINGER_LIMITS[2], 0.3),
    ("thumb_cmc", (-0.8, 0.9), 1.0),
    ("thumb_mcp", (-0.2, 1.3), 0.6),
    ("middle_mcp", FINGER_LIMITS[0], 1.0),
    ("middle_pip", FINGER_LIMITS[1], 0.6),
]


def _f(*v):
    return " ".join(f"{x:.9g}" for x in v)


def _cylinder(length, radius):
    """Mass, centre and diagonal inertia of a uniform cylinder along +x (glove10.rs cylinder)."""
    mass = HAND_DENSITY * math.pi * radius * radius * length
    transverse = mass * (3.0 * radius * radius + length * length) / 12.0
    axial = 0.5 * mass * radius * radius
    return mass, (0.5 * length, 0.0, 0.0), (axial, transverse, transverse)


def _inertial(mass, com, diag):
    return f'<inertial pos="{_f(*com)}" mass="{mass:.9g}" diaginertia="{_f(*diag)}"/>'


def _joint(name, limits, primary):
    # Armature and damping belong to a DOF; a coupled joint is not one.
    extra = f' armature="{ARMATURE}" damping="{JOINT_DAMPING}"' if primary else ""
    return (
        f'<joint name="{name}" type="hinge" axis="0 1 0" limited="true" '
        f'range="{_f(*limits)}"{extra}/>'
    )


def _finger(name, mcp, ratios, radii, tip_radius, limits, primary, contact_tips, links_collide):
    lengths = [r * HAND_LENGTH for r in ratios]
    segs = ["proximal", "middle", "distal"]
    joints = ["mcp", "pip", "dip"]
    out = []
    pos = mcp
    for s in range(3):
        m, com, diag = _cylinder(lengths[s], radii[s])
        out.append(f'<body name="{name}_{segs[s]}" pos="{_f(*pos)}" gravcomp="1">')
        out.append(_inertial(m, com, diag))
        out.append(_joint(f"{name}_{joints[s]}", limits[s], primary[s]))
        end = lengths[s] - 2.0 * tip_radius if s == 2 else lengths[s]
        out.append(
            f'<geom name="{name}_{segs[s]}" type="capsule" fromto="0 0 0 {end:.9g} 0 0" size="{radii[s]:.9g}" '
            f'{_flags(links_collide)} condim="3" group="1"/>'
        )
        pos = (lengths[s], 0.0, 0.0)
    out.append(_tip(name, lengths[2], tip_radius, name in contact_tips))
    out.extend(["</body>"] * 3)
    return out


def _flags(collides):
    """Collides with the object (contype 1 meets the object's conaffinity 1) or not at all."""
    return 'contype="1" conaffinity="0"' if collides else 'contype="0" conaffinity="0"'


def _tip(name, length, radius, collides):
    flags = _flags(collides)
    return (
        f'<geom name="tip_{name}" type="sphere" pos="{length - radius:.9g} 0 0" size="{radius:.9g}" '
        f"{flags} condim=\"3\"/>"
    )


def glove10_body(contact_tips, whole_hand=False):
    """The hand's bodies, to go inside a forearm body placed by the caller. The fingertips named
    in `contact_tips` collide with the object; with `whole_hand` the palm and the phalanges do
    too (issue 21 item 5's contact geometry, which the DFS does not have yet)."""
    a, b, c = PALM_BOX
    palm_mass = HAND_DENSITY * a * b * c
    palm_diag = (
        palm_mass * (b * b + c * c) / 12.0,
        palm_mass * (a * a + c * c) / 12.0,
        palm_mass * (a * a + b * b) / 12.0,
    )
    x = []
    # Wrist roll, pitch, yaw at the wrist centre, in that order (a serial chain in glove10:
    # MuJoCo applies a body's joints in order, each about its axis turned by those before).
    x.append('<body name="palm" pos="0 0 0" gravcomp="1">')
    x.append(_inertial(palm_mass, (0.5 * a, -0.002, 0.0), palm_diag))
    for name, axis, (lo, hi), _ in [
        ("wrist_roll", "1 0 0", DOFS[0][1], None),
        ("wrist_pitch", "0 1 0", DOFS[1][1], None),
        ("wrist_yaw", "0 0 1", DOFS[2][1], None),
    ]:
        x.append(
            f'<joint name="{name}" type="hinge" axis="{axis}" limited="true" range="{_f(lo, hi)}" '
            f'armature="{ARMATURE}" damping="{JOINT_DAMPING}"/>'
        )
    x.append(
        f'<geom name="palm" type="box" pos="{_f(0.5 * a, 0, 0)}" size="{_f(0.5 * a, 0.5 * b, 0.5 * c)}" '
        f'{_flags(whole_hand)} condim="3" group="1"/>'
    )
    ea, eb, ec = EMINENCE_BOX
    for ename, side in (("thenar", 1.0), ("hypothenar", -1.0)):
        epos = (0.5 * ea, side * 0.5 * (b - eb), -0.5 * c - EMINENCE_RISE + 0.5 * ec)
        x.append(
            f'<geom name="{ename}" type="box" pos="{_f(*epos)}" size="{_f(0.5 * ea, 0.5 * eb, 0.5 * ec)}" '
            f'{_flags(whole_hand)} condim="3" group="1"/>'
        )
    # Index: three DOFs.
    name, mcp, ratios, radii, tr = FINGERS[0]
    x += _finger(name, mcp, ratios, radii, tr, FINGER_LIMITS, [True, True, True], contact_tips, whole_hand)
    # Thumb: CMC and MCP DOFs, IP coupled 1:1 to MCP; pitched 30 degrees palmar at rest.
    lengths = [r * HAND_LENGTH for r in THUMB_RATIOS]
    half = 0.5 * THUMB_REST_PITCH
    quat = (math.cos(half), 0.0, math.sin(half), 0.0)
    tlim = [DOFS[6][1], DOFS[7][1], DOFS[7][1]]
    segs = ["metacarpal", "proximal", "distal"]
    jn = ["thumb_cmc", "thumb_mcp", "thumb_ip"]
    for s in range(3):
        m, com, diag = _cylinder(lengths[s], THUMB_RADII[s])
        pos = THUMB_CMC_IN_PALM if s == 0 else (lengths[s - 1], 0.0, 0.0)
        q = f' quat="{_f(*quat)}"' if s == 0 else ""
        x.append(f'<body name="thumb_{segs[s]}" pos="{_f(*pos)}"{q} gravcomp="1">')
        x.append(_inertial(m, com, diag))
        x.append(_joint(jn[s], tlim[s], s < 2))
        end = lengths[s] - 2.0 * THUMB_TIP_RADIUS if s == 2 else lengths[s]
        x.append(
            f'<geom name="thumb_{segs[s]}" type="capsule" fromto="0 0 0 {end:.9g} 0 0" size="{THUMB_RADII[s]:.9g}" '
            f'{_flags(whole_hand)} condim="3" group="1"/>'
        )
    x.append(_tip("thumb", lengths[2], THUMB_TIP_RADIUS, "thumb" in contact_tips))
    x.extend(["</body>"] * 3)
    # Middle (two DOFs), ring and little copy its MCP and PIP; every DIP follows its PIP at 2/3.
    dip_lim = (0.0, DIP_PIP_RATIO * FINGER_LIMITS[1][1])
    limits = [FINGER_LIMITS[0], FINGER_LIMITS[1], dip_lim]
    for i, (name, mcp, ratios, radii, tr) in enumerate(FINGERS[1:]):
        primary = [i == 0, i == 0, False]
        x += _finger(name, mcp, ratios, radii, tr, limits, primary, contact_tips, whole_hand)
    x.append("</body>")
    return "\n".join(x)


def glove10_equalities():
    """glove10's coupled joints as (stiff) joint equality constraints."""
    eq = []
    for f in ["middle", "ring", "little"]:
        eq.append(f'<joint joint1="{f}_dip" joint2="{f}_pip" polycoef="0 {DIP_PIP_RATIO:.12g} 0 0 0" solref="0.002 1"/>')
    for f in ["ring", "little"]:
        for j in ["mcp", "pip"]:
            eq.append(f'<joint joint1="{f}_{j}" joint2="middle_{j}" polycoef="0 1 0 0 0" solref="0.002 1"/>')
    eq.append('<joint joint1="thumb_ip" joint2="thumb_mcp" polycoef="0 1 0 0 0" solref="0.002 1"/>')
    return "\n".join(eq)
