//! The stored skills as recognition sees them: each skill's approach template, its feature
//! vector (the one `similar` compares) and its kind, in columns scanned per decision.
//!
//! # Cost
//!
//! A decision compares the stream's template with every stored one: a pass over a column of
//! `f32` per template value seen so far (at most [`TEMPLATE_DIM`]), which the compiler
//! vectorises. `icms bench recognition` measures it with 10 000 stored skills.

use std::collections::BTreeMap;

use crate::store::FEATURE_DIM;

use super::features::{GRIP_DIM, SCENE_DIM, TEMPLATE_DIM, TEMPLATE_SCALE};

/// One stored skill as recognition needs it.
#[derive(Debug, Clone, PartialEq)]
pub struct StoredTemplate {
    /// The skill's id.
    pub skill_id: i64,
    /// Its kind: object shape and grasp type (`box/precision-2vf`).
    pub kind: String,
    /// The name of the object it grasped, if its session named its objects.
    pub object_name: Option<String>,
    /// Its approach template (NaN where not seen).
    pub template: [f32; TEMPLATE_DIM],
    /// Its feature vector (`segmentation::FEATURE_DIMENSIONS`).
    pub feature: [f32; FEATURE_DIM],
}

/// Dimensions of the feature vector known about a grasp shortly after its fingertips closed:
/// the object (ln mass, μ, shape), the contacts (count, mean normal components) and the grasp
/// quality on them. What the grasp does next (hold time, lift, transport, rotation) and its
/// mean held force are not known yet.
pub const GRASP_STAGE_DIMS: [usize; 11] = [0, 1, 2, 3, 4, 10, 11, 12, 13, 14, 15];

/// Dimensions of the feature vector that say what a grasp does after it closes: hold time,
/// lift, transport, rotation of the object.
pub const NEXT_DIMS: [usize; 4] = [6, 7, 8, 9];

/// The stored skills, in columns, their rows grouped by object shape. Ids need not be sorted.
#[derive(Debug, Clone, Default)]
pub struct RecognitionIndex {
    ids: Vec<i64>,
    kinds: Vec<u32>,
    kind_names: Vec<String>,
    object_names: Vec<Option<String>>,
    /// Per skill: its object's shape ([`shape_code`]).
    shapes: Vec<u8>,
    /// Per template value: the column of every skill's value divided by its scale.
    template_cols: Vec<Vec<f32>>,
    /// Per feature dimension: the column.
    feature_cols: Vec<Vec<f32>>,
    /// Per shape code (0-3): the least and greatest value of each feature dimension over its
    /// rows (`-inf, inf` where one is NaN), so that a ranking can pass over a shape's rows none
    /// of which can come near enough ([`Self::rank_features`]).
    feature_bounds: [[(f32, f32); FEATURE_DIM]; 4],
}

/// Bounds of a group with no rows: nothing is near them.
const EMPTY_BOUNDS: [(f32, f32); FEATURE_DIM] = [(f32::INFINITY, f32::NEG_INFINITY); FEATURE_DIM];

/// A stored skill ranked against a query.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ranked {
    /// Row in the index.
    pub row: usize,
    /// Distance: the mean squared scaled difference over the values compared (templates), or
    /// the Euclidean distance over the dimensions compared (features).
    pub distance: f32,
}

/// Reusable buffers of a ranking (sized to the index once, then no allocation), and where a
/// ranking done a part at a time is ([`RecognitionIndex::go_on`]).
#[derive(Debug, Default)]
pub struct Scratch {
    sum: Vec<f32>,
    count: Vec<f32>,
    order: Vec<Ranked>,
    /// The ranking begun: what it compares.
    query: Query,
    /// Where it is.
    step: RankStep,
}

impl Scratch {
    /// The skills ranked, nearest first, once [`RecognitionIndex::go_on`] said the ranking is
    /// done.
    pub fn ranked(&self) -> &[Ranked] {
        &self.order
    }
}

/// What a ranking compares.
#[derive(Debug, Default, Clone, Copy)]
enum Query {
    /// None begun.
    #[default]
    None,
    /// Templates ([`RecognitionIndex::rank_templates`]): the query scaled, the rows of its
    /// shape.
    Templates {
        scaled: [f32; TEMPLATE_DIM],
        top: usize,
        min_compared: usize,
        lo: usize,
        hi: usize,
    },
    /// Features ([`RecognitionIndex::rank_features`]) over `dims[..n_dims]`, the shapes' rows
    /// (bound, first row, end) nearest first.
    Features {
        query: [f32; FEATURE_DIM],
        dims: [usize; FEATURE_DIM],
        n_dims: usize,
        top: usize,
        groups: [(f32, usize, usize); 4],
    },
}

/// Where a ranking is: a pass and its cursor (rows from the first of the range scanned).
#[derive(Debug, Default, Clone, Copy)]
enum RankStep {
    /// Done (or none begun).
    #[default]
    Done,
    /// Summing template column `col` (columns before it done): rows before `at` added.
    TemplateSum { col: usize, at: usize },
    /// Taking the rows before `at` into the ranking.
    TemplateCollect { at: usize },
    /// Feature group `group` (in the order of `Query::Features::groups`) to begin.
    FeatureGroup { group: usize },
    /// Summing the group's dimension `dims[d]`: rows before `at` added.
    FeatureSum { group: usize, d: usize, at: usize },
    /// Taking the group's rows before `at` into the ranking.
    FeatureCollect { group: usize, at: usize },
}

/// A ranking's work ([`RecognitionIndex::go_on`]), in values read: a unit (about 0.1 µs, the
/// grasp quality's, with the columns not in cache) is this many values of a column added.
const VALUES_PER_UNIT: usize = 64;

/// What taking a row into the ranking costs, in values.
const COLLECT: usize = 2;

/// Rows a step of a ranking's pass goes over.
const CHUNK: usize = 256;

/// Up to this `top`, the nearest are kept as the rows come ([`offer`]); above, all are kept
/// and the nearest selected at the end of each pass, in one step.
const OFFER_TOP: usize = 64;

impl RecognitionIndex {
    /// An index of `skills`.
    pub fn new(skills: impl IntoIterator<Item = StoredTemplate>) -> RecognitionIndex {
        let mut index = RecognitionIndex {
            template_cols: vec![Vec::new(); TEMPLATE_DIM],
            feature_cols: vec![Vec::new(); FEATURE_DIM],
            feature_bounds: [EMPTY_BOUNDS; 4],
            ..Default::default()
        };
        let mut skills: Vec<StoredTemplate> = skills.into_iter().collect();
        // Grouped by shape, the last of a repeated id kept (as inserting them in turn would).
        skills.reverse();
        let mut seen = std::collections::HashSet::new();
        skills.retain(|s| seen.insert(s.skill_id));
        skills.reverse();
        skills.sort_by_key(|s| shape_code(&s.template));
        for s in skills {
            let at = index.len();
            index.put(at, s);
        }
        index
    }

    /// Adds a skill (or replaces the one with its id).
    pub fn insert(&mut self, s: StoredTemplate) {
        self.remove(&[s.skill_id]);
        // Rows stay grouped by shape (a decision scans its shape's rows only): a new skill
        // goes at the end of its shape's rows.
        let at = self
            .shapes
            .partition_point(|&c| c <= shape_code(&s.template));
        self.put(at, s);
    }

    /// Puts a skill at row `at` (its shape's rows must stay contiguous).
    fn put(&mut self, at: usize, s: StoredTemplate) {
        if self.template_cols.is_empty() {
            self.template_cols = vec![Vec::new(); TEMPLATE_DIM];
            self.feature_cols = vec![Vec::new(); FEATURE_DIM];
        }
        let kind = match self.kind_names.iter().position(|k| *k == s.kind) {
            Some(k) => k,
            None => {
                self.kind_names.push(s.kind.clone());
                self.kind_names.len() - 1
            }
        };
        let shape = shape_code(&s.template);
        self.ids.insert(at, s.skill_id);
        self.kinds.insert(at, kind as u32);
        self.object_names.insert(at, s.object_name);
        self.shapes.insert(at, shape);
        for (j, col) in self.template_cols.iter_mut().enumerate() {
            col.insert(at, s.template[j] / TEMPLATE_SCALE[j]);
        }
        for (j, col) in self.feature_cols.iter_mut().enumerate() {
            col.insert(at, s.feature[j]);
        }
        widen(&mut self.feature_bounds[usize::from(shape)], &s.feature);
    }

    /// Recomputes [`Self::feature_bounds`] from the rows (after a removal).
    fn rebound(&mut self) {
        self.feature_bounds = [EMPTY_BOUNDS; 4];
        for row in 0..self.len() {
            let feature = self.feature(row);
            widen(
                &mut self.feature_bounds[usize::from(self.shapes[row])],
                &feature,
            );
        }
    }

    /// Removes skills by id (unknown ids are ignored).
    pub fn remove(&mut self, ids: &[i64]) {
        if ids.is_empty() || self.ids.is_empty() {
            return;
        }
        let keep: Vec<bool> = self.ids.iter().map(|id| !ids.contains(id)).collect();
        if keep.iter().all(|k| *k) {
            return;
        }
        fn retain<T>(v: &mut Vec<T>, keep: &[bool]) {
            let mut i = 0;
            v.retain(|_| {
                i += 1;
                keep[i - 1]
            });
        }
        retain(&mut self.ids, &keep);
        retain(&mut self.kinds, &keep);
        retain(&mut self.object_names, &keep);
        retain(&mut self.shapes, &keep);
        for col in self.template_cols.iter_mut().chain(&mut self.feature_cols) {
            retain(col, &keep);
        }
        self.rebound();
    }

    /// Number of skills.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// Whether it holds no skill.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// The skill id of a row.
    pub fn skill_id(&self, row: usize) -> i64 {
        self.ids[row]
    }

    /// The kind of a row (`box/precision-2vf`).
    pub fn kind(&self, row: usize) -> &str {
        &self.kind_names[self.kinds[row] as usize]
    }

    /// The kind index of a row (kinds are numbered as they first appear).
    pub fn kind_index(&self, row: usize) -> u32 {
        self.kinds[row]
    }

    /// The object name of a row.
    pub fn object_name(&self, row: usize) -> Option<&str> {
        self.object_names[row].as_deref()
    }

    /// The row of a skill id.
    pub fn row_of(&self, skill_id: i64) -> Option<usize> {
        self.ids.iter().position(|&id| id == skill_id)
    }

    /// The feature vector of a row.
    pub fn feature(&self, row: usize) -> [f32; FEATURE_DIM] {
        std::array::from_fn(|j| self.feature_cols[j][row])
    }

    /// The number of objects in the scene a row's skill was done in (its template's
    /// [`SCENE_DIM`]), if stored.
    pub fn scene_objects(&self, row: usize) -> Option<usize> {
        let v = self.template_cols.get(SCENE_DIM)?[row] * TEMPLATE_SCALE[SCENE_DIM];
        (v.is_finite() && v >= 0.0).then(|| v.round() as usize)
    }

    /// The held force per weight (feature dimension 5) of the stored skills of an object
    /// shape (feature dimensions 13-15 equal to `shape`) as a line in 1/μ (dimension 1),
    /// `(a, b)` of `a + b / μ` by least squares; `None` with fewer than three such skills or
    /// no spread in μ. A person grips for the friction they expect: the grip per weight goes
    /// with 1/μ (`dfs_core::operator`, Johansson & Westling 1984).
    pub fn held_force_line(&self, shape: [f32; 3]) -> Option<(f32, f32)> {
        let (mut n, mut sx, mut sy, mut sxx, mut sxy) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
        for row in 0..self.len() {
            if (0..3).any(|k| self.feature_cols[13 + k][row] != shape[k]) {
                continue;
            }
            let mu = f64::from(self.feature_cols[1][row]);
            if mu <= 0.05 {
                continue;
            }
            let (x, y) = (1.0 / mu, f64::from(self.feature_cols[5][row]));
            n += 1.0;
            sx += x;
            sy += y;
            sxx += x * x;
            sxy += x * y;
        }
        let det = n * sxx - sx * sx;
        if n < 3.0 || det.abs() < 1e-12 * n * n {
            return None;
        }
        let b = (n * sxy - sx * sy) / det;
        let a = (sy - b * sx) / n;
        Some((a as f32, b as f32))
    }

    /// The held force per weight (feature dimension 5) of the stored skills of an object
    /// shape (feature dimensions 13-15 equal to `shape`) and grasp type (`power`: more than
    /// three contacts, dimension 2) as a multiple of their grip (the template's grip value,
    /// [`GRIP_DIM`]): the median of the ratios, `None` without a stored skill with both.
    /// Allocates: called when a recogniser is made.
    pub fn held_per_grip(&self, shape: [f32; 3], power: bool) -> Option<f32> {
        let grips = self.template_cols.get(GRIP_DIM)?;
        let mut ratios: Vec<f32> = (0..self.len())
            .filter(|&row| {
                (0..3).all(|k| self.feature_cols[13 + k][row] == shape[k])
                    && (self.feature_cols[2][row] > 3.0) == power
            })
            .map(|row| self.feature_cols[5][row] / (grips[row] * TEMPLATE_SCALE[GRIP_DIM]))
            .filter(|r| r.is_finite() && *r > 0.0)
            .collect();
        if ratios.is_empty() {
            return None;
        }
        ratios.sort_by(f32::total_cmp);
        let n = ratios.len();
        Some(if n % 2 == 1 {
            ratios[n / 2]
        } else {
            0.5 * (ratios[n / 2 - 1] + ratios[n / 2])
        })
    }

    /// Skills per kind.
    pub fn kinds(&self) -> BTreeMap<String, usize> {
        let mut m = BTreeMap::new();
        for &k in &self.kinds {
            *m.entry(self.kind_names[k as usize].clone()).or_insert(0) += 1;
        }
        m
    }

    /// The `top` skills whose templates are nearest `query` (NaN values of either side left
    /// out), nearest first, into `scratch.order`. Only skills of the query's object shape take
    /// part (a grasp of a ball is no grasp of a box, however alike the reaches), and skills
    /// with fewer than `min_compared` values in common are left out.
    pub fn rank_templates<'s>(
        &self,
        query: &[f32; TEMPLATE_DIM],
        top: usize,
        min_compared: usize,
        scratch: &'s mut Scratch,
    ) -> &'s [Ranked] {
        self.begin_templates(query, top, min_compared, scratch);
        let mut unlimited = usize::MAX;
        while !self.go_on(scratch, &mut unlimited) {}
        &scratch.order
    }

    /// Begins [`Self::rank_templates`] in `scratch`, to be done a part at a time
    /// ([`Self::go_on`]).
    pub fn begin_templates(
        &self,
        query: &[f32; TEMPLATE_DIM],
        top: usize,
        min_compared: usize,
        scratch: &mut Scratch,
    ) {
        // Only the rows of the query's shape (contiguous, see `insert`).
        let shape = shape_code(query);
        let lo = self.shapes.partition_point(|&c| c < shape);
        let hi = self.shapes.partition_point(|&c| c <= shape);
        scratch.query = Query::Templates {
            scaled: std::array::from_fn(|j| query[j] / TEMPLATE_SCALE[j]),
            top,
            min_compared,
            lo,
            hi,
        };
        scratch.sum.clear();
        scratch.sum.resize(hi - lo, 0.0);
        scratch.count.clear();
        scratch.count.resize(hi - lo, 0.0);
        scratch.order.clear();
        scratch.step = RankStep::TemplateSum { col: 0, at: 0 };
    }

    /// The `top` skills whose features are nearest `query` over `dims` (Euclidean, as
    /// `similar` measures, on those dimensions only), nearest first.
    pub fn rank_features<'s>(
        &self,
        query: &[f32; FEATURE_DIM],
        dims: &[usize],
        top: usize,
        scratch: &'s mut Scratch,
    ) -> &'s [Ranked] {
        self.begin_features(query, dims, top, scratch);
        let mut unlimited = usize::MAX;
        while !self.go_on(scratch, &mut unlimited) {}
        &scratch.order
    }

    /// Begins [`Self::rank_features`] in `scratch`, to be done a part at a time
    /// ([`Self::go_on`]). At most [`FEATURE_DIM`] dimensions are compared.
    pub fn begin_features(
        &self,
        query: &[f32; FEATURE_DIM],
        dims: &[usize],
        top: usize,
        scratch: &mut Scratch,
    ) {
        let n_dims = dims.len().min(FEATURE_DIM);
        let mut kept = [0usize; FEATURE_DIM];
        kept[..n_dims].copy_from_slice(&dims[..n_dims]);
        let dims = &kept[..n_dims];
        // Shape by shape (rows are grouped by shape), nearest group first: a group none of
        // whose rows can be nearer than the `top`-th found so far is passed over. Its bound
        // (the distance to the box of its rows' values) is at most any row's distance, term
        // by term and summed in the same order, so what is passed over could not have been
        // ranked: the result is the full scan's, rows and distances alike (the
        // test `pruned_ranking_is_the_full_scans` compares them). With the shape's one-hot
        // dimensions compared, the other shapes' rows are √2 away at least.
        let mut groups = [(0.0f32, 0usize, 0usize); 4];
        for (code, g) in groups.iter_mut().enumerate() {
            let lo = self.shapes.partition_point(|&c| usize::from(c) < code);
            let hi = self.shapes.partition_point(|&c| usize::from(c) <= code);
            let bounds = &self.feature_bounds[code];
            let mut lb = 0.0f32;
            for &j in dims {
                let (min, max) = bounds[j];
                let gap = (min - query[j]).max(query[j] - max).max(0.0);
                lb += gap * gap;
            }
            *g = (lb.sqrt(), lo, hi);
        }
        groups.sort_by(|a, b| a.0.total_cmp(&b.0));
        scratch.query = Query::Features {
            query: *query,
            dims: kept,
            n_dims,
            top,
            groups,
        };
        scratch.order.clear();
        scratch.step = RankStep::FeatureGroup { group: 0 };
    }

    /// Goes on with the ranking begun in `scratch` ([`Self::begin_templates`],
    /// [`Self::begin_features`]) for about `budget` units of work (of about 0.1 µs: 64 values
    /// of a column compared; at least one step of 256 rows), takes what it spent off
    /// `budget`, and stops as soon as it is spent; whether the ranking is done
    /// ([`Scratch::ranked`] then). The same operations in the same
    /// order as in one call, so the same rows and distances. The index must not change
    /// meanwhile.
    pub fn go_on(&self, scratch: &mut Scratch, budget: &mut usize) -> bool {
        let limit = budget.saturating_mul(VALUES_PER_UNIT);
        let mut spent = 0usize;
        let done = self.rank_step(scratch, limit, &mut spent);
        *budget = budget.saturating_sub(spent.div_ceil(VALUES_PER_UNIT));
        done
    }

    /// [`Self::go_on`] with the work counted in values (`limit`, `spent`).
    fn rank_step(&self, scratch: &mut Scratch, limit: usize, spent: &mut usize) -> bool {
        let Scratch {
            sum,
            count,
            order,
            query,
            step,
        } = scratch;
        loop {
            let used_up = *spent > 0 && *spent >= limit;
            match (*step, &*query) {
                (RankStep::Done, _) | (_, Query::None) => {
                    *step = RankStep::Done;
                    return true;
                }
                (RankStep::TemplateSum { col, at }, Query::Templates { scaled, lo, hi, .. }) => {
                    let n = hi - lo;
                    if col == TEMPLATE_DIM {
                        *step = RankStep::TemplateCollect { at: 0 };
                        continue;
                    }
                    let q = scaled[col];
                    if q.is_nan() || at == n {
                        *step = RankStep::TemplateSum {
                            col: col + 1,
                            at: 0,
                        };
                        continue;
                    }
                    if used_up {
                        return false;
                    }
                    let end = (at + CHUNK).min(n);
                    let values = &self.template_cols[col][lo + at..lo + end];
                    for ((s, c), &v) in sum[at..end].iter_mut().zip(&mut count[at..end]).zip(values)
                    {
                        let d = v - q;
                        let d2 = d * d;
                        // NaN (not seen in the stored skill) adds nothing and does not count.
                        let seen = !d2.is_nan();
                        *s += if seen { d2 } else { 0.0 };
                        *c += seen as u8 as f32;
                    }
                    *spent += end - at;
                    *step = RankStep::TemplateSum { col, at: end };
                }
                (
                    RankStep::TemplateCollect { at },
                    &Query::Templates {
                        top,
                        min_compared,
                        lo,
                        hi,
                        ..
                    },
                ) => {
                    let n = hi - lo;
                    if at == n {
                        if top > OFFER_TOP {
                            select_top(order, top);
                        }
                        *step = RankStep::Done;
                        continue;
                    }
                    if used_up {
                        return false;
                    }
                    let end = (at + CHUNK).min(n);
                    let min = min_compared as f32;
                    for k in at..end {
                        let (s, c) = (sum[k], count[k]);
                        if c >= min && c > 0.0 {
                            keep_ranked(
                                order,
                                top,
                                Ranked {
                                    row: lo + k,
                                    distance: s / c,
                                },
                            );
                        }
                    }
                    *spent += COLLECT * (end - at);
                    *step = RankStep::TemplateCollect { at: end };
                }
                (RankStep::FeatureGroup { group }, &Query::Features { top, groups, .. }) => {
                    let Some(&(bound, lo, hi)) = groups.get(group) else {
                        *step = RankStep::Done;
                        continue;
                    };
                    let next = RankStep::FeatureGroup { group: group + 1 };
                    if lo == hi {
                        *step = next;
                        continue;
                    }
                    let kth = if top > 0 && order.len() >= top {
                        order[top - 1].distance
                    } else {
                        f32::INFINITY
                    };
                    // NaN bounds compare false: such a group is scanned.
                    if bound > kth {
                        *step = next;
                        continue;
                    }
                    if used_up {
                        return false;
                    }
                    sum.clear();
                    sum.resize(hi - lo, 0.0);
                    *spent += (hi - lo) / 4;
                    *step = RankStep::FeatureSum { group, d: 0, at: 0 };
                }
                (
                    RankStep::FeatureSum { group, d, at },
                    Query::Features {
                        query,
                        dims,
                        n_dims,
                        groups,
                        ..
                    },
                ) => {
                    let (_, lo, hi) = groups[group];
                    let n = hi - lo;
                    if d == *n_dims {
                        *step = RankStep::FeatureCollect { group, at: 0 };
                        continue;
                    }
                    if at == n {
                        *step = RankStep::FeatureSum {
                            group,
                            d: d + 1,
                            at: 0,
                        };
                        continue;
                    }
                    if used_up {
                        return false;
                    }
                    let end = (at + CHUNK).min(n);
                    let j = dims[d];
                    let q = query[j];
                    for (s, &v) in sum[at..end]
                        .iter_mut()
                        .zip(&self.feature_cols[j][lo + at..lo + end])
                    {
                        let diff = v - q;
                        *s += diff * diff;
                    }
                    *spent += end - at;
                    *step = RankStep::FeatureSum { group, d, at: end };
                }
                (RankStep::FeatureCollect { group, at }, &Query::Features { top, groups, .. }) => {
                    let (_, lo, hi) = groups[group];
                    let n = hi - lo;
                    if at == n {
                        if top > OFFER_TOP {
                            select_top(order, top);
                        }
                        *step = RankStep::FeatureGroup { group: group + 1 };
                        continue;
                    }
                    if used_up {
                        return false;
                    }
                    let end = (at + CHUNK).min(n);
                    for (k, &s) in sum.iter().enumerate().take(end).skip(at) {
                        keep_ranked(
                            order,
                            top,
                            Ranked {
                                row: lo + k,
                                distance: s.sqrt(),
                            },
                        );
                    }
                    *spent += COLLECT * (end - at);
                    *step = RankStep::FeatureCollect { group, at: end };
                }
                // A step of the other kind of ranking: none begun.
                _ => {
                    *step = RankStep::Done;
                    return true;
                }
            }
        }
    }
}

/// Takes a ranked row into `order`: kept as it comes among the `top` nearest ([`offer`]), or,
/// for a `top` above [`OFFER_TOP`], appended (the pass selects the nearest at its end).
#[inline]
fn keep_ranked(order: &mut Vec<Ranked>, top: usize, x: Ranked) {
    if top > OFFER_TOP {
        order.push(x);
    } else {
        offer(order, top, x);
    }
}

/// Offers `x` to `order`, the `top` nearest offered so far, sorted ([`nearer`]): what
/// [`select_top`] keeps of all of them.
#[inline]
fn offer(order: &mut Vec<Ranked>, top: usize, x: Ranked) {
    if order.len() >= top {
        match order.last() {
            Some(last) if nearer(&x, last).is_lt() => {
                order.pop();
            }
            _ => return,
        }
    }
    let at = order.partition_point(|y| nearer(y, &x).is_lt());
    order.insert(at, x);
}

/// Nearer first, ties by row: a total order, so that the `top` nearest are one set in one
/// order however they are found.
fn nearer(a: &Ranked, b: &Ranked) -> std::cmp::Ordering {
    a.distance
        .total_cmp(&b.distance)
        .then_with(|| a.row.cmp(&b.row))
}

/// Widens `bounds` to hold `feature` (a NaN value makes its dimension unbounded).
fn widen(bounds: &mut [(f32, f32); FEATURE_DIM], feature: &[f32; FEATURE_DIM]) {
    for (b, &v) in bounds.iter_mut().zip(feature) {
        *b = if v.is_nan() || b.0.is_nan() {
            (f32::NEG_INFINITY, f32::INFINITY)
        } else {
            (b.0.min(v), b.1.max(v))
        };
    }
}

/// The shape a template's one-hot values name: 0 sphere, 1 box, 2 cylinder, 3 none.
fn shape_code(template: &[f32; TEMPLATE_DIM]) -> u8 {
    (0..3u8).find(|&k| template[k as usize] > 0.5).unwrap_or(3)
}

/// Keeps the `top` nearest of `order` ([`nearer`]), sorted.
fn select_top(order: &mut Vec<Ranked>, top: usize) -> &[Ranked] {
    if order.len() > top && top > 0 {
        order.select_nth_unstable_by(top - 1, nearer);
        order.truncate(top);
    } else if top == 0 {
        order.clear();
    }
    order.sort_unstable_by(nearer);
    order
}

#[cfg(test)]
mod tests {
    use super::*;

    fn skill(id: i64, kind: &str, fill: f32) -> StoredTemplate {
        let mut template = [f32::NAN; TEMPLATE_DIM];
        for (j, v) in template.iter_mut().enumerate().take(10) {
            *v = fill * TEMPLATE_SCALE[j];
        }
        StoredTemplate {
            skill_id: id,
            kind: kind.into(),
            object_name: None,
            template,
            feature: [fill; FEATURE_DIM],
        }
    }

    #[test]
    fn templates_rank_by_mean_scaled_difference_leaving_out_what_is_not_seen() {
        let index =
            RecognitionIndex::new([skill(1, "a", 0.0), skill(2, "b", 1.0), skill(3, "a", 3.0)]);
        let mut q = [f32::NAN; TEMPLATE_DIM];
        for (j, v) in q.iter_mut().enumerate().take(5) {
            *v = 0.9 * TEMPLATE_SCALE[j];
        }
        let mut scratch = Scratch::default();
        let r = index.rank_templates(&q, 2, 1, &mut scratch).to_vec();
        assert_eq!(r.len(), 2);
        assert_eq!(index.skill_id(r[0].row), 2);
        assert!((r[0].distance - 0.01).abs() < 1e-5, "{r:?}");
        assert_eq!(index.skill_id(r[1].row), 1);
        assert!((r[1].distance - 0.81).abs() < 1e-5);
        // Asking for more values in common than any skill has leaves nothing.
        assert!(index.rank_templates(&q, 2, 11, &mut scratch).is_empty());
        assert_eq!(index.kinds().get("a"), Some(&2));
    }

    #[test]
    fn features_rank_over_the_dimensions_given_and_removal_keeps_columns_aligned() {
        let mut index =
            RecognitionIndex::new([skill(1, "a", 0.0), skill(2, "b", 1.0), skill(3, "a", 3.0)]);
        index.remove(&[2]);
        assert_eq!(index.len(), 2);
        let mut scratch = Scratch::default();
        let q = [2.0; FEATURE_DIM];
        let r = index.rank_features(&q, &[0, 1], 5, &mut scratch).to_vec();
        assert_eq!(index.skill_id(r[0].row), 3);
        assert!((r[0].distance - 2f32.sqrt()).abs() < 1e-5);
        assert_eq!(index.feature(r[1].row), [0.0; FEATURE_DIM]);
        assert_eq!(index.kind(r[1].row), "a");
    }

    /// The ranking that passes over far shapes gives the full scan's rows and distances, on
    /// random indexes of every shape mix (with removals, replacements and NaN values), for
    /// queries of every shape and dimension set.
    #[test]
    fn pruned_ranking_is_the_full_scans() {
        use proptest::prelude::*;
        let full = |index: &RecognitionIndex, q: &[f32; FEATURE_DIM], dims: &[usize], top| {
            let mut all: Vec<Ranked> = (0..index.len())
                .map(|row| {
                    let mut s = 0.0f32;
                    for &j in dims {
                        let d = index.feature_cols[j][row] - q[j];
                        s += d * d;
                    }
                    Ranked {
                        row,
                        distance: s.sqrt(),
                    }
                })
                .collect();
            select_top(&mut all, top).to_vec()
        };
        let row = (
            0usize..4,
            prop::array::uniform16(-2.0f32..2.0),
            any::<bool>(),
        );
        proptest!(ProptestConfig::with_cases(200), |(
            rows in prop::collection::vec(row, 0..60),
            query in (0usize..4, prop::array::uniform16(-2.0f32..2.0)),
            top in prop_oneof![0usize..8, 60usize..70],
            remove in prop::collection::vec(0i64..60, 0..5),
            all_dims in any::<bool>(),
        )| {
            let stored = |id: usize, (shape, values, nan): &(usize, [f32; 16], bool)| {
                let mut template = [f32::NAN; TEMPLATE_DIM];
                template[..3].fill(0.0);
                if *shape < 3 {
                    template[*shape] = 1.0;
                }
                let mut feature = [0.0f32; FEATURE_DIM];
                for (j, f) in feature.iter_mut().enumerate() {
                    *f = values[j % 16];
                }
                for k in 0..3 {
                    feature[13 + k] = if k == *shape { 1.0 } else { 0.0 };
                }
                if *nan {
                    feature[2] = f32::NAN;
                }
                StoredTemplate {
                    skill_id: id as i64,
                    kind: format!("k{shape}"),
                    object_name: None,
                    template,
                    feature,
                }
            };
            let (half, rest) = rows.split_at(rows.len() / 2);
            let mut index =
                RecognitionIndex::new(half.iter().enumerate().map(|(i, r)| stored(i, r)));
            for (i, r) in rest.iter().enumerate() {
                index.insert(stored(half.len() + i, r));
            }
            index.remove(&remove);
            let mut q = [0.0f32; FEATURE_DIM];
            for (j, v) in q.iter_mut().enumerate() {
                *v = query.1[j % 16];
            }
            for k in 0..3 {
                q[13 + k] = if k == query.0 { 1.0 } else { 0.0 };
            }
            let dims: Vec<usize> = if all_dims {
                (0..FEATURE_DIM).collect()
            } else {
                GRASP_STAGE_DIMS.to_vec()
            };
            let mut scratch = Scratch::default();
            let got = index.rank_features(&q, &dims, top, &mut scratch).to_vec();
            let want = full(&index, &q, &dims, top);
            prop_assert_eq!(got.len(), want.len());
            for (g, w) in got.iter().zip(&want) {
                prop_assert_eq!(g.row, w.row);
                prop_assert!(g.distance.to_bits() == w.distance.to_bits()
                    || (g.distance.is_nan() && w.distance.is_nan()));
            }
        });
    }

    /// An index of `rows` (shape code, the values of a template after its shape, 16 of a
    /// feature), half put at once and half inserted, then `remove`d.
    fn random_index(rows: &[(usize, Vec<f32>, Vec<f32>)], remove: &[i64]) -> RecognitionIndex {
        let stored = |id: usize, (shape, t, f): &(usize, Vec<f32>, Vec<f32>)| StoredTemplate {
            skill_id: id as i64,
            kind: format!("k{}", (shape + id) % 5),
            object_name: None,
            template: template(*shape, t),
            feature: std::array::from_fn(|j| f[j]),
        };
        let (half, rest) = rows.split_at(rows.len() / 2);
        let mut index = RecognitionIndex::new(half.iter().enumerate().map(|(i, r)| stored(i, r)));
        for (i, r) in rest.iter().enumerate() {
            index.insert(stored(half.len() + i, r));
        }
        index.remove(remove);
        index
    }

    /// A template of shape code `shape` with `values` (scaled) after its one-hot values.
    fn template(shape: usize, values: &[f32]) -> [f32; TEMPLATE_DIM] {
        let mut t = [0.0f32; TEMPLATE_DIM];
        if shape < 3 {
            t[shape] = 1.0;
        }
        for (j, v) in t.iter_mut().enumerate().skip(3) {
            *v = values[j - 3] * TEMPLATE_SCALE[j];
        }
        t
    }

    /// Random rows for [`random_index`]: values in ±3 or NaN.
    fn rows(
        n: std::ops::Range<usize>,
    ) -> impl proptest::strategy::Strategy<Value = Vec<(usize, Vec<f32>, Vec<f32>)>> {
        use proptest::prelude::*;
        let value = || prop_oneof![1 => Just(f32::NAN), 6 => -3.0f32..3.0];
        let row = (
            0usize..4,
            prop::collection::vec(value(), TEMPLATE_DIM - 3),
            prop::collection::vec(value(), FEATURE_DIM),
        );
        prop::collection::vec(row, n)
    }

    /// The template ranking gives the rows and distances of a plain pass over every row of
    /// the query's shape, on random indexes with NaN values on either side, for every `top`
    /// and `min_compared`.
    #[test]
    fn template_ranking_is_the_full_scans() {
        use proptest::prelude::*;
        let full = |index: &RecognitionIndex, q: &[f32; TEMPLATE_DIM], top, min: usize| {
            let mut all = Vec::new();
            for row in 0..index.len() {
                if index.shapes[row] != shape_code(q) {
                    continue;
                }
                let (mut s, mut c) = (0.0f32, 0.0f32);
                for j in 0..TEMPLATE_DIM {
                    let d = index.template_cols[j][row] - q[j] / TEMPLATE_SCALE[j];
                    if !(d * d).is_nan() {
                        s += d * d;
                        c += 1.0;
                    }
                }
                if c >= min as f32 && c > 0.0 {
                    all.push(Ranked {
                        row,
                        distance: s / c,
                    });
                }
            }
            select_top(&mut all, top).to_vec()
        };
        proptest!(ProptestConfig::with_cases(100), |(
            rows in rows(0..900),
            query in (0usize..4, prop::collection::vec(prop_oneof![Just(f32::NAN), -3.0f32..3.0], TEMPLATE_DIM - 3)),
            top in prop_oneof![0usize..20, 60usize..300],
            min in 0usize..12,
            remove in prop::collection::vec(0i64..900, 0..5),
        )| {
            let index = random_index(&rows, &remove);
            let q = template(query.0, &query.1);
            let mut scratch = Scratch::default();
            let got = index.rank_templates(&q, top, min, &mut scratch).to_vec();
            let want = full(&index, &q, top, min);
            prop_assert_eq!(got.len(), want.len());
            for (g, w) in got.iter().zip(&want) {
                prop_assert_eq!(g.row, w.row);
                prop_assert_eq!(g.distance.to_bits(), w.distance.to_bits());
            }
        });
    }

    /// A ranking done a part at a time ([`RecognitionIndex::go_on`] with a few units a call)
    /// is the one done in one call, rows and distances, and takes as many calls as its work
    /// asks.
    #[test]
    fn a_ranking_in_parts_is_the_ranking_in_one_call() {
        use proptest::prelude::*;
        proptest!(ProptestConfig::with_cases(100), |(
            rows in rows(0..900),
            shape in 0usize..4,
            values in prop::collection::vec(-3.0f32..3.0, TEMPLATE_DIM - 3),
            top in prop_oneof![0usize..20, 60usize..300],
            budget in 1usize..40,
            all_dims in any::<bool>(),
        )| {
            let index = random_index(&rows, &[]);
            let same = |a: &[Ranked], b: &[Ranked]| {
                a.len() == b.len()
                    && a.iter().zip(b).all(|(x, y)| {
                        x.row == y.row && x.distance.to_bits() == y.distance.to_bits()
                    })
            };
            let q = template(shape, &values);
            let whole = index.rank_templates(&q, top, 3, &mut Scratch::default()).to_vec();
            let mut scratch = Scratch::default();
            index.begin_templates(&q, top, 3, &mut scratch);
            let mut calls = 1;
            while !index.go_on(&mut scratch, &mut { budget }) {
                calls += 1;
            }
            prop_assert!(same(scratch.ranked(), &whole));
            // The columns of the shape's rows (26 at least) and a pass taking them: that many
            // calls at least.
            let n = (0..index.len()).filter(|&r| index.shapes[r] == shape_code(&q)).count();
            prop_assert!(calls >= n * 26 / (budget * VALUES_PER_UNIT + CHUNK), "{} calls", calls);

            let mut fq = [0.0f32; FEATURE_DIM];
            for (j, v) in fq.iter_mut().enumerate() {
                *v = values[j];
            }
            let dims: Vec<usize> = if all_dims {
                (0..FEATURE_DIM).collect()
            } else {
                GRASP_STAGE_DIMS.to_vec()
            };
            let whole = index.rank_features(&fq, &dims, top, &mut Scratch::default()).to_vec();
            index.begin_features(&fq, &dims, top, &mut scratch);
            while !index.go_on(&mut scratch, &mut { budget }) {}
            prop_assert!(same(scratch.ranked(), &whole));
        });
    }

    #[test]
    fn rows_stay_grouped_by_shape_and_a_query_sees_its_shape_only() {
        let shaped = |id: i64, shape: usize, v: f32| {
            let mut t = [f32::NAN; TEMPLATE_DIM];
            t[..3].fill(0.0);
            t[shape] = 1.0;
            for (j, x) in t.iter_mut().enumerate().take(10).skip(3) {
                *x = v * TEMPLATE_SCALE[j];
            }
            StoredTemplate {
                skill_id: id,
                kind: format!("k{shape}"),
                object_name: None,
                template: t,
                feature: [v; FEATURE_DIM],
            }
        };
        let mut index =
            RecognitionIndex::new([shaped(1, 2, 0.0), shaped(2, 0, 0.0), shaped(3, 1, 0.0)]);
        index.insert(shaped(4, 0, 1.0));
        index.insert(shaped(5, 2, 1.0));
        // Replacing a skill moves it to its (new) shape's rows.
        index.insert(shaped(1, 1, 2.0));
        assert_eq!(index.len(), 5);
        let codes: Vec<u8> = (0..index.len()).map(|r| index.shapes[r]).collect();
        assert!(codes.windows(2).all(|w| w[0] <= w[1]), "{codes:?}");
        let mut scratch = Scratch::default();
        for (shape, ids) in [(0usize, vec![2, 4]), (1, vec![3, 1]), (2, vec![5])] {
            let q = shaped(0, shape, 0.5).template;
            let mut got: Vec<i64> = index
                .rank_templates(&q, 10, 1, &mut scratch)
                .iter()
                .map(|r| index.skill_id(r.row))
                .collect();
            let mut want = ids.clone();
            got.sort_unstable();
            want.sort_unstable();
            assert_eq!(got, want, "shape {shape}");
        }
        assert_eq!(index.feature(index.row_of(1).unwrap()), [2.0; FEATURE_DIM]);
    }

    /// A stored pinch or power grasp of a sphere or a box: its held force per weight `held`,
    /// its template's grip `grip` (NaN: not stored) in a scene of `scene` objects.
    fn grasp(
        id: i64,
        sphere: bool,
        contacts: f32,
        held: f32,
        grip: f32,
        scene: f32,
    ) -> StoredTemplate {
        let mut template = [f32::NAN; TEMPLATE_DIM];
        template[0] = f32::from(u8::from(sphere));
        template[1] = f32::from(u8::from(!sphere));
        template[2] = 0.0;
        template[GRIP_DIM] = grip;
        template[SCENE_DIM] = scene;
        let mut feature = [0.0; FEATURE_DIM];
        feature[2] = contacts;
        feature[5] = held;
        feature[13] = template[0];
        feature[14] = template[1];
        StoredTemplate {
            skill_id: id,
            kind: "k".into(),
            object_name: None,
            template,
            feature,
        }
    }

    #[test]
    fn the_held_force_per_grip_is_the_median_ratio_of_the_shapes_grasps_of_the_type() {
        let index = RecognitionIndex::new([
            grasp(1, true, 2.0, 3.0, 4.0, 1.0),
            grasp(2, true, 2.0, 3.0, 5.0, 1.0),
            grasp(3, true, 2.0, 1.0, 10.0, 3.0),
            grasp(4, true, 2.0, 9.0, f32::NAN, 1.0),
            grasp(5, true, 7.0, 6.0, 8.0, 1.0),
            grasp(6, false, 2.0, 2.0, 4.0, f32::NAN),
            grasp(7, false, 2.0, 3.0, 4.0, 1.0),
        ]);
        let sphere = [1.0, 0.0, 0.0];
        // Sphere pinches: 0.75, 0.6 and 0.1 (the one without a grip left out): 0.6.
        assert!((index.held_per_grip(sphere, false).unwrap() - 0.6).abs() < 1e-6);
        // Sphere power grasps (more than three contacts): the one, 0.75.
        assert!((index.held_per_grip(sphere, true).unwrap() - 0.75).abs() < 1e-6);
        // Box pinches: 0.5 and 0.75, the middle of the two.
        let boxed = [0.0, 1.0, 0.0];
        assert!((index.held_per_grip(boxed, false).unwrap() - 0.625).abs() < 1e-6);
        assert_eq!(index.held_per_grip(boxed, true), None);
        assert_eq!(index.held_per_grip([0.0, 0.0, 1.0], false), None);
        let scene = |id| index.scene_objects(index.row_of(id).unwrap());
        assert_eq!((scene(1), scene(3), scene(6)), (Some(1), Some(3), None));
    }
}
