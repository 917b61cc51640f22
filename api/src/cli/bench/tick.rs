//! `icms bench tick`: the DFS tick timed on a held-object scene that evolves, with the same
//! statistic as the MuJoCo peer of the same scene (`benches/peers/mujoco_peer.py`).
//!
//! # The `fingertips` scene
//!
//! glove10, palm up and rolled 20° ([`BASE_ROLL`]), holds a ball (4 cm radius, 0.3 kg:
//! `sphere-lift`'s ball, with the paper's μ = 1.5 of §3.4, point contacts with friction) on four
//! fingertips: the thumb on one side, the index, middle and ring fingertips on the other, all
//! about 2 cm below the ball's centre, so that it rests in them as in a cup. The paper's own
//! sphere (1 kg, 10 cm radius) cannot be held so: glove10's thumb cannot span it, and on the
//! four long fingertips alone (the `frozen` scene) it is not in equilibrium.
//!
//! The posture is solved once: the middle finger's coupled MCP and PIP are set
//! ([`COUPLED_MCP`], [`COUPLED_PIP`]); the ball's centre is where it touches the middle and
//! ring fingertips ([`CENTRE_Y`] across the hand); the thumb and index fingertips are put on
//! it by inverse kinematics ([`CONTACT_BELOW`] below its centre). The operator holds it with
//! joint torques `τ = g(t) τ_ff + K_p (θ_set − θ) − K_d θ̇`: `τ_ff = Σ Jᵀ f` for the fingertip
//! forces nearest to a squeeze of [`SQUEEZE_N`] along each contact normal, every force within
//! its finger's flexion plane, that carry the ball's weight without turning it (the weight's
//! part across the flexion planes, and the turn about the palm's normal that the thumb's plane
//! beside the fingers' makes, are left to friction), and an impedance about the set posture.
//! The grip `g(t) = 1 + GRIP_SWING sin(2π t / GRIP_PERIOD_S)` swings slowly, so the contact
//! forces and the ball's place in the hand change all the time.
//!
//! The glove samples are made once, before timing, by running that operator in the closed loop
//! (each tick's θ is the DFS's motor command of the tick before, as a glove whose motors track
//! the DFS's commands); the timed run replays them, from the same start, into a fresh DFS: the
//! same ticks as the closed loop, bit for bit (checked at the end). Nothing is reset: the ball
//! moves, every tick detects the contacts and solves the forces, the object's dynamics and the
//! fingers'. After every batch the bench checks (untimed) that at least three fingertips still
//! hold the ball and that it has not moved 10 mm in the hand, and fails otherwise.
//!
//! # The `power-grasp` scene
//!
//! glove10's power grasp of a cylinder (`dfs_core::fixtures::glove10_power_grasp`: a 4.4 cm,
//! 0.3 kg cylinder across the palm, μ = 1, the fingers closed on it by constant flexion torques
//! and settled for 1.5 s, whole-hand contact on). The operator then holds it with
//! `τ = g(t) τ_close + K_p (θ_set − θ) − K_d θ̇` about where the fingers came to rest, with the same
//! swinging grip as the `fingertips` scene; samples made by the closed loop beforehand and
//! replayed as there. After every batch the bench checks that the palm or a phalanx still
//! presses the cylinder and that it has not moved 10 mm in the hand.
//!
//! # Timing
//!
//! Batches of [`BATCH_TICKS`] ticks, alternately timed as a whole (two clock reads per batch:
//! `median_ns` is the median over those batches of the batch's time per tick, the statistic
//! the MuJoCo peer prints, and `min_ns` the fastest of them) and tick by tick (`p99_ns` and
//! `median_tick_ns` are percentiles of those single ticks, each with its own two clock reads,
//! about 20-40 ns of them). Allocations are counted over every timed tick.

use super::super::CliError;
use dfs_core::contact::{ContactModel, Friction};
use dfs_core::dfs::{Dfs, DfsParams, GloveSample};
use dfs_core::fixtures::{glove10_holding_paper_sphere, FrozenSample};
use dfs_core::hand::{HandModel, Kinematics};
use dfs_core::math::{Isometry, Real, Rotation, Vector};
use dfs_core::object::{ObjectState, RigidObject, Shape};
use serde::Serialize;
use std::hint::black_box;
use std::time::Instant;

/// Scenes of `icms bench tick`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum TickScene {
    /// glove10, palm up, holding a 4 cm, 0.3 kg ball on four fingertips (thumb, index, middle,
    /// ring) with a slowly swinging grip: an evolving held-object scene, the same as the MuJoCo
    /// peer's `--scene fingertips`.
    Fingertips,
    /// glove10, palm up, its fingers closed around a cylinder lying across the palm and pressing
    /// it into the palm and the thumb's base, with a swinging grip: whole-hand contact (palm,
    /// phalanges and fingertips; issue 21 item 5). `dfs_core::fixtures::glove10_power_grasp`
    /// builds it; the same as the MuJoCo peer's `--scene power-grasp`.
    PowerGrasp,
    /// The benchmark before issue 21: one frozen glove sample of the paper's sphere on four
    /// long fingertips, the object reset every tick (kept so that issue 2's figures can be
    /// compared with).
    Frozen,
}

impl TickScene {
    /// Its name on the command line (`power-grasp`).
    fn name(self) -> &'static str {
        match self {
            TickScene::Fingertips => "fingertips",
            TickScene::PowerGrasp => "power-grasp",
            TickScene::Frozen => "frozen",
        }
    }
}

/// Result of `icms bench tick`.
#[derive(Debug, Serialize)]
pub struct TickBench {
    /// The scene.
    pub scene: TickScene,
    /// Median over the batches timed as a whole of the time per tick (ns): the statistic of
    /// the MuJoCo peer.
    pub median_ns: f64,
    /// 99th percentile of the ticks timed one by one (ns).
    pub p99_ns: f64,
    /// The fastest batch timed as a whole, per tick (ns): the least disturbed by the rest of
    /// the machine (the MuJoCo peer prints its own).
    pub min_ns: f64,
    /// Median of the ticks timed one by one (ns): the statistic of `icms bench tick` before
    /// issue 21 (each tick carries its two clock reads).
    pub median_tick_ns: f64,
    /// Mean over the batches timed as a whole (ns).
    pub mean_ns: f64,
    /// Heap allocations per timed tick (counted by the global allocator).
    pub allocations_per_tick: f64,
    /// Ticks timed (both kinds of batch).
    pub iterations: usize,
    /// Ticks per batch.
    pub batch_ticks: usize,
    /// Ticks run before timing (the grasp settles; caches warm).
    pub warmup_ticks: usize,
    /// Transmitting contacts at the end of the run.
    pub contacts: usize,
    /// Fewest transmitting contacts seen at the end of a batch.
    pub min_contacts: usize,
    /// Largest distance the object moved in the hand base's frame from its start (mm), at the
    /// ends of the batches.
    pub max_object_shift_mm: f64,
}

/// Ticks per timed batch: 0.2-0.3 ms, much shorter than the time slice another process gets
/// on a shared core (a few ms), so most batches are untouched and the median is theirs (the
/// MuJoCo peer's batches are as many steps).
pub const BATCH_TICKS: usize = 100;
/// Ticks run before the timed ones: the grasp settles (2 s).
pub const WARMUP_TICKS: usize = 2000;
/// Most timed ticks of a held scene: its glove samples are made beforehand and kept in memory
/// (160 bytes per tick).
pub const MAX_HELD_TICKS: usize = 2_000_000;

/// Coupled middle/ring/little MCP angle of the set posture (rad).
pub const COUPLED_MCP: Real = 0.8;
/// Coupled middle/ring/little PIP angle of the set posture (rad).
pub const COUPLED_PIP: Real = 1.0;
/// The ball's centre across the hand (palm y, m): between the thumb's and the ring finger's
/// flexion planes, so that their contacts lean out of their planes alike.
pub const CENTRE_Y: Real = 0.010;
/// How far below the ball's centre the thumb and index fingertips touch it (m).
pub const CONTACT_BELOW: Real = 0.02;
/// Radius of the ball (m).
pub const BALL_RADIUS: Real = 0.04;
/// Mass of the ball (kg).
pub const BALL_MASS: Real = 0.3;
/// Coulomb friction between the fingertips and the ball (the paper's §3.4 value).
pub const BALL_MU: Real = 1.5;
/// Normal force each fingertip's feed-forward squeeze aims at (N).
pub const SQUEEZE_N: Real = 3.0;
/// Joint stiffness of the operator's impedance per N·m of the DOF's torque limit (1/rad).
pub const KP_PER_LIMIT: Real = 5.0;
/// Joint damping of the operator's impedance per N·m of the DOF's torque limit (s/rad).
pub const KD_PER_LIMIT: Real = 0.02;
/// Relative swing of the grip (the feed-forward torques).
pub const GRIP_SWING: Real = 0.2;
/// Period of the grip's swing (s).
pub const GRIP_PERIOD_S: Real = 2.0;
/// The hand base's roll from palm up (rad, about the forearm's axis), the thumb's side down: the
/// thumb's flexion plane lies just beside the index finger's, so the four contacts surround the
/// ball's centre only narrowly across the hand (4 mm on the ring finger's side); tilted, the
/// ball's weight acts nearer the middle of them (MuJoCo's ball, resting on hard contacts, rolls
/// out over that edge within seconds untilted).
pub const BASE_ROLL: Real = 0.35;
/// The fingertips that hold the ball.
pub const CONTACT_TIPS: [&str; 4] = ["thumb", "index", "middle", "ring"];

/// The `fingertips` scene: where everything is and how the operator holds the ball. Printed by
/// `icms bench tick --scene fingertips --describe` for the MuJoCo peer.
#[derive(Debug, Clone, Serialize)]
pub struct HeldScene {
    /// The scene's name, tick, gravity and hand base.
    #[serde(flatten)]
    pub frame: SceneFrame,
    /// The ball: radius (m).
    pub ball_radius: Real,
    /// The ball's mass (kg).
    pub ball_mass: Real,
    /// Coulomb friction, fingertips on the ball.
    pub ball_mu: Real,
    /// The ball's centre at the start (world, m).
    pub ball_position: [Real; 3],
    /// The fingertips that touch it at the start.
    pub contact_tips: Vec<&'static str>,
    /// How the operator holds it.
    #[serde(flatten)]
    pub grip: HeldGrip,
}

/// What both described scenes start with: the name, the DFS's tick and gravity, and where
/// the hand base is.
#[derive(Debug, Clone, Serialize)]
pub struct SceneFrame {
    /// Scene name.
    pub scene: &'static str,
    /// Tick (s).
    pub dt: Real,
    /// Gravity (world, m/s²).
    pub gravity: [Real; 3],
    /// The hand model.
    pub hand: &'static str,
    /// Hand base (forearm) position in the world (m).
    pub base_position: [Real; 3],
    /// Orientation of the hand base (w, x, y, z).
    pub base_quaternion: [Real; 4],
}

impl SceneFrame {
    /// Scene `scene` of the glove10 hand with DFS parameters `params` and hand base `base`.
    fn glove10(scene: &'static str, params: &DfsParams, base: &Isometry) -> Self {
        let quat = base.rotation.quaternion();
        SceneFrame {
            scene,
            dt: params.dt,
            gravity: params.gravity.into(),
            hand: "glove10",
            base_position: base.translation.vector.into(),
            base_quaternion: [quat.w, quat.i, quat.j, quat.k],
        }
    }
}

/// What both described scenes end with: how the operator holds the object, a PD grip about a
/// set posture whose strength swings.
#[derive(Debug, Clone, Serialize)]
pub struct HeldGrip {
    /// DOF names, in θ order.
    pub dofs: Vec<String>,
    /// The set posture θ_set (rad); also the start (`power-grasp`: where the fingers came to
    /// rest).
    pub q: Vec<Real>,
    /// Feed-forward torques τ_ff (N·m) (`power-grasp`: the closing torques, scaled by the
    /// grip).
    pub tau_ff: Vec<Real>,
    /// Joint stiffness K_p (N·m/rad).
    pub kp: Vec<Real>,
    /// Joint damping K_d (N·m·s/rad).
    pub kd: Vec<Real>,
    /// Relative swing of the grip.
    pub grip_swing: Real,
    /// Period of the grip's swing (s).
    pub grip_period_s: Real,
}

/// The scene with the DFS it starts from.
struct Held {
    scene: HeldScene,
    dfs: Dfs,
    base: Isometry,
}

fn dof(hand: &HandModel, name: &str) -> Result<usize, CliError> {
    hand.dof_names
        .iter()
        .position(|d| d == name)
        .ok_or_else(|| CliError(format!("glove10 has no DOF {name:?}")))
}

fn tip(hand: &HandModel, name: &str) -> Result<usize, CliError> {
    hand.fingertips
        .iter()
        .position(|t| t.name == name)
        .ok_or_else(|| CliError(format!("glove10 has no fingertip {name:?}")))
}

/// Damped Newton over two unknowns with a forward-difference Jacobian, each kept within
/// `[lo, hi]`; returns the unknowns and the largest residual left.
fn solve2(
    mut f: impl FnMut([Real; 2]) -> [Real; 2],
    mut x: [Real; 2],
    lo: [Real; 2],
    hi: [Real; 2],
) -> ([Real; 2], Real) {
    for _ in 0..200 {
        let r = f(x);
        if r[0].abs().max(r[1].abs()) < 1e-12 {
            break;
        }
        let mut j = nalgebra::Matrix2::<Real>::zeros();
        for c in 0..2 {
            let mut xh = x;
            xh[c] += 1e-7;
            let rh = f(xh);
            j[(0, c)] = (rh[0] - r[0]) / 1e-7;
            j[(1, c)] = (rh[1] - r[1]) / 1e-7;
        }
        let jt = j.transpose();
        let Some(step) = (jt * j + nalgebra::Matrix2::identity() * 1e-12)
            .lu()
            .solve(&(jt * nalgebra::Vector2::new(r[0], r[1])))
        else {
            break;
        };
        for c in 0..2 {
            x[c] = (x[c] - step[c].clamp(-0.1, 0.1)).clamp(lo[c], hi[c]);
        }
    }
    let r = f(x);
    (x, r[0].abs().max(r[1].abs()))
}

/// Builds the `fingertips` scene (see the module documentation).
fn fingertips() -> Result<Held, CliError> {
    let hand = HandModel::glove10();
    // Everything is solved in the palm frame (the base at the identity), then turned palm up.
    let mut kin = Box::<Kinematics>::default();
    let Posture { q, centre, tips } = fingertips_posture(&hand, &mut kin)?;
    // Every fingertip of the grasp touches; the others are clear by 5 mm.
    hand.forward_kinematics(&Isometry::identity(), &q, &mut kin);
    check_ball_gaps(&hand, &kin, centre, &tips)?;
    // Palm up, rolled by BASE_ROLL: the palm frame turned by π + BASE_ROLL about x.
    let base = Isometry::from_parts(
        Vector::zeros().into(),
        Rotation::from_axis_angle(&Vector::x_axis(), std::f64::consts::PI + BASE_ROLL),
    );
    let params = DfsParams {
        contact_model: ContactModel::PointWithFriction,
        friction: Friction {
            mu: BALL_MU,
            mu_torsion: 0.0,
        },
        ..DfsParams::default()
    };
    hand.tip_jacobians(&mut kin);
    let tau_ff = feed_forward_torques(&hand, &kin, centre, &tips, &base, &params)?;
    let kp: Vec<Real> = hand.torque_limit.iter().map(|l| l * KP_PER_LIMIT).collect();
    let kd: Vec<Real> = hand.torque_limit.iter().map(|l| l * KD_PER_LIMIT).collect();
    let centre_w = base * dfs_core::math::Point::from(centre);
    let object = RigidObject::new(
        Shape::Sphere {
            radius: BALL_RADIUS,
        },
        BALL_MASS,
    )?;
    let start = ObjectState::at_rest(Isometry::translation(centre_w.x, centre_w.y, centre_w.z));
    let dfs = Dfs::new(hand.clone(), object, start, params)?;
    let scene = HeldScene {
        frame: SceneFrame::glove10("fingertips", &params, &base),
        ball_radius: BALL_RADIUS,
        ball_mass: BALL_MASS,
        ball_mu: BALL_MU,
        ball_position: centre_w.coords.into(),
        contact_tips: CONTACT_TIPS.to_vec(),
        grip: HeldGrip {
            dofs: hand.dof_names.clone(),
            q,
            tau_ff,
            kp,
            kd,
            grip_swing: GRIP_SWING,
            grip_period_s: GRIP_PERIOD_S,
        },
    };
    Ok(Held { scene, dfs, base })
}

/// The `fingertips` scene's set posture, solved in the palm frame.
struct Posture {
    /// The set posture θ_set (rad).
    q: Vec<Real>,
    /// The ball's centre (palm frame, m).
    centre: Vector,
    /// The fingertips that hold the ball, those of [`CONTACT_TIPS`] in order.
    tips: Vec<usize>,
}

/// Solves the set posture (see the module documentation): the middle finger's coupled MCP and
/// PIP set, the ball's centre on the middle and ring fingertips, the thumb and index
/// fingertips put on it by inverse kinematics. `kin` is scratch.
fn fingertips_posture(hand: &HandModel, kin: &mut Kinematics) -> Result<Posture, CliError> {
    let n = hand.dof();
    let (mcp, pip) = (dof(hand, "middle_mcp")?, dof(hand, "middle_pip")?);
    let (t_cmc, t_mcp) = (dof(hand, "thumb_cmc")?, dof(hand, "thumb_mcp")?);
    let (i_mcp, i_pip, i_dip) = (
        dof(hand, "index_mcp")?,
        dof(hand, "index_pip")?,
        dof(hand, "index_dip")?,
    );
    let tips: Vec<usize> = CONTACT_TIPS
        .iter()
        .map(|t| tip(hand, t))
        .collect::<Result<_, _>>()?;
    let [thumb, index, middle, ring] = [tips[0], tips[1], tips[2], tips[3]];
    let mut q = vec![0.0; n];
    q[mcp] = COUPLED_MCP;
    q[pip] = COUPLED_PIP;
    let centre = ball_centre(hand, kin, &q, middle, ring)?;
    let lim = |d: usize| (hand.dof_lower[d], hand.dof_upper[d]);
    let y_thumb = tip_at(hand, kin, &q, thumb).y;
    let target = spot(hand, centre, thumb, y_thumb, -1.0)?;
    let (x, err_t) = solve2(
        |[a, b]| {
            let mut qq = q.clone();
            qq[t_cmc] = a;
            qq[t_mcp] = b;
            let p = tip_at(hand, kin, &qq, thumb);
            [p.x - target.x, p.z - target.z]
        },
        [0.3, 0.5],
        [lim(t_cmc).0, lim(t_mcp).0],
        [lim(t_cmc).1, lim(t_mcp).1],
    );
    q[t_cmc] = x[0];
    q[t_mcp] = x[1];
    let y_index = tip_at(hand, kin, &q, index).y;
    let target = spot(hand, centre, index, y_index, 1.0)?;
    // The index curls like the coupled fingers: its DIP at ⅔ of its PIP.
    let dip_of = |p: Real| (p * 2.0 / 3.0).min(hand.dof_upper[i_dip]);
    let (x, err_i) = solve2(
        |[a, b]| {
            let mut qq = q.clone();
            qq[i_mcp] = a;
            qq[i_pip] = b;
            qq[i_dip] = dip_of(b);
            let p = tip_at(hand, kin, &qq, index);
            [p.x - target.x, p.z - target.z]
        },
        [0.8, 1.0],
        [lim(i_mcp).0, lim(i_pip).0],
        [lim(i_mcp).1, lim(i_pip).1],
    );
    q[i_mcp] = x[0];
    q[i_pip] = x[1];
    q[i_dip] = dip_of(x[1]);
    if err_t.max(err_i) > 1e-9 {
        return Err(CliError(format!(
            "fingertips scene: the thumb or the index cannot reach its spot ({:.1e} m off)",
            err_t.max(err_i)
        )));
    }
    Ok(Posture { q, centre, tips })
}

/// How far fingertip `k`'s centre is from the ball's when it touches it (m).
fn reach(hand: &HandModel, k: usize) -> Real {
    BALL_RADIUS + hand.fingertips[k].radius
}

/// Fingertip `k`'s centre in the palm frame at posture `q` (`kin` is scratch).
fn tip_at(hand: &HandModel, kin: &mut Kinematics, q: &[Real], k: usize) -> Vector {
    hand.forward_kinematics(&Isometry::identity(), q, kin);
    kin.tip_centres[k].coords
}

/// The ball's centre (palm frame) at [`CENTRE_Y`] across the hand where it touches the
/// `middle` and `ring` fingertips of posture `q`.
fn ball_centre(
    hand: &HandModel,
    kin: &mut Kinematics,
    q: &[Real],
    middle: usize,
    ring: usize,
) -> Result<Vector, CliError> {
    let (pm, pr) = (tip_at(hand, kin, q, middle), tip_at(hand, kin, q, ring));
    let ((cx, cz), err) = {
        let (x, err) = solve2(
            |[x, z]| {
                let c = Vector::new(x, CENTRE_Y, z);
                [
                    (pm - c).norm() - reach(hand, middle),
                    (pr - c).norm() - reach(hand, ring),
                ]
            },
            [pm.x - BALL_RADIUS, pm.z - CONTACT_BELOW],
            [-1.0, -1.0],
            [1.0, 1.0],
        );
        ((x[0], x[1]), err)
    };
    if err > 1e-9 {
        return Err(CliError(format!(
            "fingertips scene: no ball centre touches the middle and ring fingertips ({err:.1e} m off)"
        )));
    }
    Ok(Vector::new(cx, CENTRE_Y, cz))
}

/// A fingertip's spot on the ball at `centre`: in its flexion plane (its centre's palm `y`),
/// [`CONTACT_BELOW`] toward the palm from the ball's centre, on the thumb's side (`side` −1,
/// −x) or the fingers' (+1, +x).
fn spot(
    hand: &HandModel,
    centre: Vector,
    k: usize,
    y: Real,
    side: Real,
) -> Result<Vector, CliError> {
    let (dy, h) = (y - centre.y, CONTACT_BELOW);
    let s = reach(hand, k).powi(2) - dy * dy - h * h;
    if s <= 0.0 {
        return Err(CliError(format!(
            "fingertips scene: fingertip {} cannot reach the ball",
            hand.fingertips[k].name
        )));
    }
    Ok(Vector::new(centre.x + side * s.sqrt(), y, centre.z + h))
}

/// Checks, on the kinematics `kin` of the set posture, that every fingertip of the grasp
/// (`tips`) touches the ball at `centre` and the others are clear of it by 5 mm.
fn check_ball_gaps(
    hand: &HandModel,
    kin: &Kinematics,
    centre: Vector,
    tips: &[usize],
) -> Result<(), CliError> {
    for (k, t) in hand.fingertips.iter().enumerate() {
        let gap = (kin.tip_centres[k].coords - centre).norm() - reach(hand, k);
        let ok = if tips.contains(&k) {
            gap.abs() < 1e-9
        } else {
            gap > 0.005
        };
        if !ok {
            return Err(CliError(format!(
                "fingertips scene: fingertip {} is {:.2} mm from the ball",
                t.name,
                gap * 1e3
            )));
        }
    }
    Ok(())
}

/// The feed-forward torques τ_ff = Σ Jᵀ f of the fingertips `tips` holding the ball at
/// `centre`, from the kinematics `kin` of the set posture (tip Jacobians computed), the hand
/// at `base` in a DFS with `params`.
///
/// Fingertip forces f_k = (x, 0, z) in the palm frame (each finger pushes in its flexion
/// plane): nearest to [`SQUEEZE_N`] along each in-plane inward normal such that they carry the
/// weight (palm +z is down once palm up) without a moment about the palm's x and y axes; the
/// moment about its z (the thumb's plane lies beside the fingers') is friction's.
fn feed_forward_torques(
    hand: &HandModel,
    kin: &Kinematics,
    centre: Vector,
    tips: &[usize],
    base: &Isometry,
    params: &DfsParams,
) -> Result<Vec<Real>, CliError> {
    let m = tips.len();
    let mut a = nalgebra::DMatrix::<Real>::zeros(4, 2 * m);
    let mut f0 = nalgebra::DVector::<Real>::zeros(2 * m);
    for (i, &k) in tips.iter().enumerate() {
        let p = kin.tip_centres[k].coords;
        let r = p - centre;
        // Columns: unit force along x, along z; rows: Σfx, Σfz, Mx, My.
        a[(0, 2 * i)] = 1.0;
        a[(1, 2 * i + 1)] = 1.0;
        a[(2, 2 * i + 1)] = r.y;
        a[(3, 2 * i)] = r.z;
        a[(3, 2 * i + 1)] = -r.x;
        let inward = nalgebra::Vector2::new(centre.x - p.x, centre.z - p.z).normalize();
        f0[2 * i] = inward.x * SQUEEZE_N;
        f0[2 * i + 1] = inward.y * SQUEEZE_N;
    }
    // The weight in the palm frame; its part across the flexion planes (palm y) is friction's.
    let weight = base.rotation.inverse() * params.gravity * BALL_MASS;
    let b = nalgebra::DVector::from_vec(vec![-weight.x, -weight.z, 0.0, 0.0]);
    let aat = &a * a.transpose();
    let y = aat
        .lu()
        .solve(&(&b - &a * &f0))
        .ok_or_else(|| CliError("fingertips scene: singular force balance".into()))?;
    let f = &f0 + a.transpose() * y;
    let mut tau_ff = vec![0.0; hand.dof()];
    for (i, &k) in tips.iter().enumerate() {
        let j = &kin.tip_jacobians[k];
        for (d, t) in tau_ff.iter_mut().enumerate() {
            *t += j[(0, d)] * f[2 * i] + j[(2, d)] * f[2 * i + 1];
        }
    }
    Ok(tau_ff)
}

/// The `power-grasp` scene: where everything is once the grasp has settled and how the operator
/// holds the cylinder. Printed by `icms bench tick --scene power-grasp --describe` for the MuJoCo
/// peer.
#[derive(Debug, Clone, Serialize)]
pub struct PowerGraspScene {
    /// The scene's name, tick, gravity and hand base.
    #[serde(flatten)]
    pub frame: SceneFrame,
    /// The cylinder's radius (m).
    pub cylinder_radius: Real,
    /// Half its length (m), along its z axis.
    pub cylinder_half_height: Real,
    /// Its mass (kg).
    pub cylinder_mass: Real,
    /// Coulomb friction, hand on the cylinder (every contact: palm, phalanges, fingertips).
    pub cylinder_mu: Real,
    /// Its centre once the grasp settled (world, m).
    pub cylinder_position: [Real; 3],
    /// Its orientation then (w, x, y, z).
    pub cylinder_quaternion: [Real; 4],
    /// Whole-hand contact stiffness (N/m) and damping (N·s/m) of the DFS.
    pub body_stiffness: Real,
    /// See `body_stiffness`.
    pub body_damping: Real,
    /// The contacts (shape names, fingertips as `tip_<name>`) pressing once settled.
    pub contacts: Vec<String>,
    /// How the operator holds it.
    #[serde(flatten)]
    pub grip: HeldGrip,
}

/// A scene's description for the MuJoCo peer (`--describe`).
#[derive(Debug, Clone, Serialize)]
#[serde(untagged)]
pub enum SceneDescription {
    /// `fingertips`.
    Fingertips(HeldScene),
    /// `power-grasp`.
    PowerGrasp(PowerGraspScene),
}

/// The scene's description (`--describe`).
pub fn describe(scene: TickScene) -> Result<SceneDescription, CliError> {
    match scene {
        TickScene::Fingertips => Ok(SceneDescription::Fingertips(fingertips()?.scene)),
        TickScene::PowerGrasp => Ok(SceneDescription::PowerGrasp(power_grasp_scene()?)),
        other => Err(not_held(other)),
    }
}

/// The settled power grasp as [`PowerGraspScene`].
fn power_grasp_scene() -> Result<PowerGraspScene, CliError> {
    let g = dfs_core::fixtures::glove10_power_grasp()?;
    let p = *g.dfs.params();
    let hand = g.dfs.hand();
    let out = g.dfs.output();
    let mut contacts: Vec<String> = (0..out.n_body)
        .filter(|&s| g.dfs.body_contacts()[s].in_contact)
        .map(|s| hand.contact_shapes[s].name.clone())
        .collect();
    contacts.extend(
        (0..out.n_tips)
            .filter(|&k| out.tips[k].in_contact)
            .map(|k| format!("tip_{}", hand.fingertips[k].name)),
    );
    let cyl = out.object.pose;
    let cq = cyl.rotation.quaternion();
    Ok(PowerGraspScene {
        frame: SceneFrame::glove10("power-grasp", &p, &g.base),
        cylinder_radius: dfs_core::fixtures::CYLINDER_RADIUS,
        cylinder_half_height: dfs_core::fixtures::CYLINDER_HALF_HEIGHT,
        cylinder_mass: dfs_core::fixtures::CYLINDER_MASS,
        cylinder_mu: dfs_core::fixtures::CYLINDER_MU,
        cylinder_position: cyl.translation.vector.into(),
        cylinder_quaternion: [cq.w, cq.i, cq.j, cq.k],
        body_stiffness: p.body_stiffness,
        body_damping: p.body_damping,
        contacts,
        grip: HeldGrip {
            dofs: hand.dof_names.clone(),
            q: g.grip.set[..g.grip.n].to_vec(),
            tau_ff: g.grip.close[..g.grip.n].to_vec(),
            kp: g.grip.kp[..g.grip.n].to_vec(),
            kd: g.grip.kd[..g.grip.n].to_vec(),
            grip_swing: GRIP_SWING,
            grip_period_s: GRIP_PERIOD_S,
        },
    })
}

fn not_held(scene: TickScene) -> CliError {
    CliError(format!(
        "scene {scene:?}: only the fingertips and power-grasp scenes can be described"
    ))
}

/// Glove samples of a held scene, made by the closed loop, and the DFS state they end in.
struct Samples {
    n: usize,
    q: Vec<Real>,
    tau: Vec<Real>,
    end: ObjectState,
}

/// Runs the operator of `held` in the closed loop for `ticks` ticks and keeps its samples.
fn closed_loop(held: &Held, ticks: usize) -> Result<Samples, CliError> {
    let s = &held.scene.grip;
    let dt = held.scene.frame.dt;
    let n = s.q.len();
    let hand = held.dfs.hand();
    let range = held.dfs.params().torque_range;
    let mut dfs = held.dfs.clone();
    let mut q = s.q.clone();
    let mut qd = vec![0.0; n];
    let mut tau = vec![0.0; n];
    let mut out = Samples {
        n,
        q: Vec::with_capacity(n * ticks),
        tau: Vec::with_capacity(n * ticks),
        end: *dfs.object_state(),
    };
    for t in 0..ticks {
        let time = t as Real * dt;
        let grip = 1.0 + s.grip_swing * (std::f64::consts::TAU * time / s.grip_period_s).sin();
        for d in 0..n {
            let lim = hand.torque_limit[d] * range;
            tau[d] =
                (grip * s.tau_ff[d] + s.kp[d] * (s.q[d] - q[d]) - s.kd[d] * qd[d]).clamp(-lim, lim);
        }
        out.q.extend_from_slice(&q);
        out.tau.extend_from_slice(&tau);
        let o = dfs
            .step(&GloveSample {
                q: &q,
                tau: &tau,
                base: held.base,
            })
            .map_err(|e| CliError(format!("fingertips scene, closed loop, tick {t}: {e}")))?;
        q.copy_from_slice(&o.motor_q[..n]);
        qd.copy_from_slice(&o.motor_qd[..n]);
    }
    out.end = *dfs.object_state();
    Ok(out)
}

/// Runs `icms bench tick` for `scene` with about `iterations` timed ticks.
pub fn bench_tick(scene: TickScene, iterations: usize) -> Result<TickBench, CliError> {
    let batch = BATCH_TICKS.min(iterations / 2).max(1);
    // An even number of batches: as many timed whole as tick by tick.
    let batches = (iterations / batch / 2).max(1) * 2;
    let timed = batches * batch;
    if scene != TickScene::Frozen && timed > MAX_HELD_TICKS {
        return Err(CliError(format!(
            "--iterations: at most {MAX_HELD_TICKS} for a held scene (its glove samples are kept in memory)"
        )));
    }
    match scene {
        TickScene::PowerGrasp => bench_power_grasp(batch, batches, timed),
        TickScene::Frozen => bench_frozen(batch, batches),
        TickScene::Fingertips => {
            let held = fingertips()?;
            let samples = closed_loop(&held, WARMUP_TICKS + timed)?;
            // The ball is still held.
            bench_replay(
                TickScene::Fingertips,
                &held.dfs,
                held.base,
                &samples,
                batch,
                batches,
                |dfs, shift| {
                    let n = dfs.output().n_contacts;
                    (n < 3 || shift > 0.010).then(|| format!("{n} contacts"))
                },
            )
        }
    }
}

/// What [`time_alternating`] measured.
struct Timings {
    /// The batches timed whole (ns per batch).
    batch_ns: Vec<u64>,
    /// The ticks of the batches timed tick by tick (ns per tick).
    tick_ns: Vec<u32>,
    /// Heap allocations during the batches (not during the checks between them).
    allocations: usize,
}

/// Runs `batches` batches of `batch` ticks of `state`, alternately timed whole (the statistic
/// the MuJoCo peer uses) and tick by tick (the percentiles); `check` runs untimed after each
/// batch and may stop the benchmark.
fn time_alternating<S>(
    state: &mut S,
    batch: usize,
    batches: usize,
    mut tick: impl FnMut(&mut S) -> Result<(), CliError>,
    mut check: impl FnMut(&mut S, usize) -> Result<(), CliError>,
) -> Result<Timings, CliError> {
    let mut batch_ns = vec![0u64; batches / 2];
    let mut tick_ns = vec![0u32; batches / 2 * batch];
    let mut region = stats_alloc::Region::new(&stats_alloc::INSTRUMENTED_SYSTEM);
    let mut allocations = 0;
    for b in 0..batches {
        if b % 2 == 0 {
            let t0 = Instant::now();
            for _ in 0..batch {
                tick(state)?;
            }
            batch_ns[b / 2] = t0.elapsed().as_nanos().min(u64::MAX as u128) as u64;
        } else {
            for t in &mut tick_ns[b / 2 * batch..(b / 2 + 1) * batch] {
                let t0 = Instant::now();
                tick(state)?;
                *t = t0.elapsed().as_nanos().min(u32::MAX as u128) as u32;
            }
        }
        allocations += region.change_and_reset().allocations;
        check(state, b)?;
    }
    Ok(Timings {
        batch_ns,
        tick_ns,
        allocations,
    })
}

/// Percentiles and the result from the timings.
fn summary(scene: TickScene, timings: Timings, batch: usize) -> TickBench {
    let Timings {
        mut batch_ns,
        mut tick_ns,
        allocations,
    } = timings;
    batch_ns.sort_unstable();
    tick_ns.sort_unstable();
    let per = |ns: u64| ns as f64 / batch as f64;
    let iterations = batch_ns.len() * batch + tick_ns.len();
    TickBench {
        scene,
        median_ns: per(batch_ns[batch_ns.len() / 2]),
        min_ns: per(batch_ns[0]),
        p99_ns: tick_ns[tick_ns.len() * 99 / 100] as f64,
        median_tick_ns: tick_ns[tick_ns.len() / 2] as f64,
        mean_ns: batch_ns.iter().map(|&b| per(b)).sum::<f64>() / batch_ns.len() as f64,
        allocations_per_tick: allocations as f64 / iterations as f64,
        iterations,
        batch_ticks: batch,
        warmup_ticks: 0,
        contacts: 0,
        min_contacts: 0,
        max_object_shift_mm: 0.0,
    }
}

/// Times `dfs` replaying the closed loop's `samples` (the first [`WARMUP_TICKS`] untimed),
/// failing once the object is no longer held: `lost` gets the DFS after a batch and the
/// object's shift in the hand (m), and answers why it is not held, if it is not.
fn bench_replay(
    scene: TickScene,
    dfs: &Dfs,
    base: Isometry,
    samples: &Samples,
    batch: usize,
    batches: usize,
    lost: impl Fn(&Dfs, Real) -> Option<String>,
) -> Result<TickBench, CliError> {
    let n = samples.n;
    let sample = |i: usize| GloveSample {
        q: &samples.q[i * n..(i + 1) * n],
        tau: &samples.tau[i * n..(i + 1) * n],
        base,
    };
    let in_hand = |s: &ObjectState| base.inverse_transform_vector(&s.pose.translation.vector);
    // The DFS and the index of its next sample.
    let mut state = (dfs.clone(), 0usize);
    let start = in_hand(state.0.object_state());
    for _ in 0..WARMUP_TICKS {
        state.0.step(&sample(state.1))?;
        state.1 += 1;
    }
    let (mut min_contacts, mut max_shift) = (usize::MAX, 0.0 as Real);
    let timings = time_alternating(
        &mut state,
        batch,
        batches,
        |(dfs, i)| {
            black_box(dfs.step(black_box(&sample(*i)))?);
            *i += 1;
            Ok(())
        },
        |(dfs, _), b| {
            let out = dfs.output();
            let shift = (in_hand(&out.object) - start).norm();
            min_contacts = min_contacts.min(out.n_contacts);
            max_shift = max_shift.max(shift);
            match lost(dfs, shift) {
                Some(why) => Err(CliError(format!(
                    "{} scene: the object is no longer held after {} timed ticks ({why}, moved {:.1} mm in the hand)",
                    scene.name(),
                    (b + 1) * batch,
                    shift * 1e3
                ))),
                None => Ok(()),
            }
        },
    )?;
    let dfs = &state.0;
    // The replay is the closed loop, tick for tick.
    if *dfs.object_state() != samples.end {
        return Err(CliError(format!(
            "{} scene: the replayed ticks ended elsewhere than the closed loop that made their samples",
            scene.name()
        )));
    }
    let mut r = summary(scene, timings, batch);
    r.warmup_ticks = WARMUP_TICKS;
    r.contacts = dfs.output().n_contacts;
    r.min_contacts = min_contacts;
    r.max_object_shift_mm = max_shift * 1e3;
    Ok(r)
}

/// The benchmark before issue 21: glove10 and the paper's sphere, one frozen sample, the
/// object reset every tick.
fn bench_frozen(batch: usize, batches: usize) -> Result<TickBench, CliError> {
    let held = glove10_holding_paper_sphere()?;
    let frozen = FrozenSample::of(&held);
    let mut dfs = held.dfs;
    let tick = |dfs: &mut Dfs| -> Result<(), CliError> {
        black_box(frozen.tick(dfs)?);
        Ok(())
    };
    let warmup = batch * batches / 10;
    for _ in 0..warmup {
        tick(&mut dfs)?;
    }
    let timings = time_alternating(&mut dfs, batch, batches, tick, |_, _| Ok(()))?;
    let contacts = dfs.output().n_contacts;
    let mut r = summary(TickScene::Frozen, timings, batch);
    r.warmup_ticks = warmup;
    r.contacts = contacts;
    r.min_contacts = contacts;
    Ok(r)
}

/// The `power-grasp` scene (module documentation).
fn bench_power_grasp(batch: usize, batches: usize, timed: usize) -> Result<TickBench, CliError> {
    use dfs_core::fixtures::glove10_power_grasp;
    let g = glove10_power_grasp()?;
    let n = g.dfs.hand().dof();
    let base = g.base;
    // The glove samples, made by the closed loop.
    let ticks = WARMUP_TICKS + timed;
    let (mut qs, mut taus) = (Vec::with_capacity(n * ticks), Vec::with_capacity(n * ticks));
    let mut dfs = g.dfs.clone();
    let mut glove = g.glove();
    for t in 0..ticks {
        let time = t as Real * dfs.params().dt;
        let grip = 1.0 + GRIP_SWING * (std::f64::consts::TAU * time / GRIP_PERIOD_S).sin();
        // The sample the tick is given: the glove's state before it, the torques for it.
        qs.extend_from_slice(&glove.q);
        g.tick(&mut dfs, &mut glove, grip)
            .map_err(|e| CliError(format!("power-grasp scene, closed loop, tick {t}: {e}")))?;
        taus.extend_from_slice(&glove.tau);
    }
    let samples = Samples {
        n,
        q: qs,
        tau: taus,
        end: *dfs.object_state(),
    };
    // Still pressed into the hand by the palm or a phalanx.
    bench_replay(
        TickScene::PowerGrasp,
        &g.dfs,
        base,
        &samples,
        batch,
        batches,
        |dfs, shift| {
            let body = dfs.body_contacts().iter().filter(|c| c.in_contact).count();
            (body == 0 || shift > 0.010).then(|| format!("{body} palm or phalanx contacts"))
        },
    )
}
