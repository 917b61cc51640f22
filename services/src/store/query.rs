//! Skill queries: filters, sort keys and opaque keyset cursors.

use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::error::StoreError;
use super::types::ObjectShape;
use dfs_core::contact::ContactModel;
use dfs_core::scenario::Phase;

/// Largest page size.
pub const MAX_LIMIT: u32 = 1000;
/// Page size when none is given.
pub const DEFAULT_LIMIT: u32 = 50;

/// Column to sort skills by; ties are broken by id in the same direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SortField {
    /// Skill id (insertion order).
    #[default]
    Id,
    /// Ferrari-Canny ε quality.
    Quality,
    /// Object mass.
    Mass,
    /// Skill duration.
    Duration,
}

/// Sort direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SortOrder {
    /// Smallest first.
    #[default]
    Asc,
    /// Largest first.
    Desc,
}

/// A sort: field and direction. Parses from `quality`, `quality:desc` or `-quality`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct SortKey {
    /// Column to sort by.
    pub field: SortField,
    /// Direction.
    pub order: SortOrder,
}

impl SortKey {
    /// A sort by `field` in `order`.
    pub fn new(field: SortField, order: SortOrder) -> Self {
        SortKey { field, order }
    }

    fn tag(self) -> String {
        let f = match self.field {
            SortField::Id => "id",
            SortField::Quality => "quality",
            SortField::Mass => "mass",
            SortField::Duration => "duration",
        };
        let o = match self.order {
            SortOrder::Asc => "asc",
            SortOrder::Desc => "desc",
        };
        format!("{f}:{o}")
    }
}

impl FromStr for SortKey {
    type Err = StoreError;

    fn from_str(s: &str) -> Result<Self, StoreError> {
        let (name, order) = if let Some(rest) = s.strip_prefix('-') {
            (rest, SortOrder::Desc)
        } else if let Some((name, dir)) = s.split_once(':') {
            let order = match dir {
                "asc" => SortOrder::Asc,
                "desc" => SortOrder::Desc,
                _ => {
                    return Err(StoreError::InvalidQuery(format!(
                        "sort direction {dir:?} is not asc or desc"
                    )))
                }
            };
            (name, order)
        } else {
            (s, SortOrder::Asc)
        };
        let field = match name {
            "id" => SortField::Id,
            "quality" => SortField::Quality,
            "mass" => SortField::Mass,
            "duration" => SortField::Duration,
            _ => {
                return Err(StoreError::InvalidQuery(format!(
                    "sort field {name:?} is not one of id, quality, mass, duration"
                )))
            }
        };
        Ok(SortKey { field, order })
    }
}

impl std::fmt::Display for SortKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.tag())
    }
}

/// Filters, sort and page of a skill query. Every filter is optional; ranges are inclusive.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SkillQuery {
    /// Object shape equals.
    pub object_shape: Option<ObjectShape>,
    /// Object mass at least, kg.
    pub mass_min: Option<f64>,
    /// Object mass at most, kg.
    pub mass_max: Option<f64>,
    /// Friction coefficient at least.
    pub mu_min: Option<f64>,
    /// Friction coefficient at most.
    pub mu_max: Option<f64>,
    /// Number of contacts equals.
    pub contact_count: Option<i64>,
    /// Contact model equals.
    pub contact_model: Option<ContactModel>,
    /// Grasp type equals.
    pub grasp_type: Option<String>,
    /// Ferrari-Canny ε at least.
    pub min_quality: Option<f64>,
    /// The skill has this phase (with `phase_min_s`/`phase_max_s`: of that duration).
    pub phase: Option<Phase>,
    /// Duration of `phase` at least, s. Needs `phase`.
    pub phase_min_s: Option<f64>,
    /// Duration of `phase` at most, s. Needs `phase`.
    pub phase_max_s: Option<f64>,
    /// Sort order (default: id ascending).
    pub sort: SortKey,
    /// Page size, 1..=1000 (default 50).
    pub limit: u32,
    /// `next_cursor` of the previous page, or `None` for the first page.
    pub cursor: Option<String>,
}

/// Filters, order and page of a session query ([`crate::store::Store::query_sessions`]). Every
/// filter is optional and matches exactly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SessionQuery {
    /// Scenario name equals (simulated sessions; a recorded one has none).
    pub scenario: Option<String>,
    /// Hand (glove) name equals.
    pub hand: Option<String>,
    /// Object shape equals.
    pub object_shape: Option<ObjectShape>,
    /// Newest (highest id) first; default oldest first.
    pub newest_first: bool,
    /// Page size, 1..=1000 (default 50).
    pub limit: u32,
    /// `next_cursor` of the previous page (same order), or `None` for the first page.
    pub cursor: Option<String>,
}

impl Default for SessionQuery {
    fn default() -> Self {
        SessionQuery {
            scenario: None,
            hand: None,
            object_shape: None,
            newest_first: false,
            limit: DEFAULT_LIMIT,
            cursor: None,
        }
    }
}

impl Default for SkillQuery {
    fn default() -> Self {
        SkillQuery {
            object_shape: None,
            mass_min: None,
            mass_max: None,
            mu_min: None,
            mu_max: None,
            contact_count: None,
            contact_model: None,
            grasp_type: None,
            min_quality: None,
            phase: None,
            phase_min_s: None,
            phase_max_s: None,
            sort: SortKey::default(),
            limit: DEFAULT_LIMIT,
            cursor: None,
        }
    }
}

/// Position after the last row of a page: its sort value and id.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum After {
    Int(i64),
    Real(f64, i64),
}

/// Encodes a keyset position with the sort it belongs to, as hex (opaque to callers).
pub(crate) fn encode_cursor(tag: &str, after: After) -> String {
    let text = match after {
        After::Int(id) => format!("v1|{tag}|{id}"),
        After::Real(v, id) => format!("v1|{tag}|{:016x}|{id}", v.to_bits()),
    };
    hex::encode(text)
}

/// Decodes a cursor made by [`encode_cursor`] for the same `tag`.
pub(crate) fn decode_cursor(tag: &str, real: bool, cursor: &str) -> Result<After, StoreError> {
    let bytes = hex::decode(cursor).map_err(|_| StoreError::BadCursor)?;
    let text = String::from_utf8(bytes).map_err(|_| StoreError::BadCursor)?;
    let mut parts = text.split('|');
    if parts.next() != Some("v1") || parts.next() != Some(tag) {
        return Err(StoreError::BadCursor);
    }
    let after = if real {
        let bits = parts
            .next()
            .and_then(|p| u64::from_str_radix(p, 16).ok())
            .ok_or(StoreError::BadCursor)?;
        let v = f64::from_bits(bits);
        let id = parts
            .next()
            .and_then(|p| p.parse().ok())
            .ok_or(StoreError::BadCursor)?;
        if !v.is_finite() {
            return Err(StoreError::BadCursor);
        }
        After::Real(v, id)
    } else {
        After::Int(
            parts
                .next()
                .and_then(|p| p.parse().ok())
                .ok_or(StoreError::BadCursor)?,
        )
    };
    if parts.next().is_some() {
        return Err(StoreError::BadCursor);
    }
    Ok(after)
}

/// Grasp type families. Segmented skills store the family as their label; a label may also
/// name the opposing virtual fingers, `<family>-<n>vf` (the synthetic bench skills do).
const GRASP_FAMILIES: [&str; 2] = ["precision", "power"];

/// The `grasp_type` filter: a family (`precision`, `power`: every label of it) or a whole
/// label (`precision-2vf`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum GraspFilter<'a> {
    /// One whole label.
    Label(&'a str),
    /// Every label of a family: the bare family name and `<family>-<n>vf`.
    Family(&'a str),
}

impl<'a> GraspFilter<'a> {
    fn parse(v: &'a str) -> Result<Self, StoreError> {
        if GRASP_FAMILIES.contains(&v) {
            return Ok(GraspFilter::Family(v));
        }
        let label = v.split_once('-').is_some_and(|(family, vf)| {
            GRASP_FAMILIES.contains(&family)
                && vf.strip_suffix("vf").is_some_and(|n| {
                    !n.is_empty() && n.len() <= 2 && n.bytes().all(|b| b.is_ascii_digit())
                })
        });
        if label {
            Ok(GraspFilter::Label(v))
        } else {
            Err(StoreError::InvalidQuery(format!(
                "grasp_type {v:?} is neither precision nor power, nor a label such as \
                 precision-2vf (family, then the number of opposing virtual fingers)"
            )))
        }
    }
}

fn check_range(name: &str, min: Option<f64>, max: Option<f64>) -> Result<(), StoreError> {
    for (bound, v) in [("min", min), ("max", max)] {
        if let Some(v) = v {
            if !v.is_finite() {
                return Err(StoreError::InvalidQuery(format!(
                    "{name} {bound} must be finite"
                )));
            }
            if v < 0.0 {
                return Err(StoreError::InvalidQuery(format!(
                    "{name} {bound} {v} is negative; every {name} is ≥ 0"
                )));
            }
        }
    }
    if let (Some(lo), Some(hi)) = (min, max) {
        if lo > hi {
            return Err(StoreError::InvalidQuery(format!(
                "{name} min {lo} is above max {hi}"
            )));
        }
    }
    Ok(())
}

/// A validated skill query: the typed parts a backend builds its one run-time query from
/// (every value bound, no SQL text from outside).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SkillFilter<'a> {
    /// Object shape equals.
    pub object_shape: Option<ObjectShape>,
    /// Object mass at least, kg.
    pub mass_min: Option<f64>,
    /// Object mass at most, kg.
    pub mass_max: Option<f64>,
    /// Friction coefficient at least.
    pub mu_min: Option<f64>,
    /// Friction coefficient at most.
    pub mu_max: Option<f64>,
    /// Number of contacts equals.
    pub contact_count: Option<i64>,
    /// Contact model equals.
    pub contact_model: Option<ContactModel>,
    /// Grasp type: a whole label or a family.
    pub grasp: Option<GraspFilter<'a>>,
    /// Ferrari-Canny ε at least.
    pub min_quality: Option<f64>,
    /// The skill has this phase, of a duration in this range.
    pub phase: Option<PhaseFilter>,
    /// Sort order.
    pub sort: SortKey,
    /// Keyset position after the previous page's last row.
    pub after: Option<After>,
    /// Rows to fetch: the page size plus one, to see whether more follow.
    pub fetch: i64,
}

/// The phase filter of a skill query.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PhaseFilter {
    /// The phase the skill has.
    pub phase: Phase,
    /// Its duration at least, s.
    pub min_s: Option<f64>,
    /// Its duration at most, s.
    pub max_s: Option<f64>,
}

/// Validates `q` into the typed parts of its query.
pub(crate) fn skill_filter(q: &SkillQuery) -> Result<SkillFilter<'_>, StoreError> {
    if q.limit == 0 || q.limit > MAX_LIMIT {
        return Err(StoreError::InvalidQuery(format!(
            "limit {} is outside 1..={MAX_LIMIT}",
            q.limit
        )));
    }
    check_range("mass", q.mass_min, q.mass_max)?;
    check_range("mu", q.mu_min, q.mu_max)?;
    check_range("quality", q.min_quality, None)?;
    check_range("phase duration", q.phase_min_s, q.phase_max_s)?;
    if let Some(n) = q.contact_count.filter(|&n| n < 0) {
        return Err(StoreError::InvalidQuery(format!(
            "contacts {n} is negative; a skill has 0 or more contacts"
        )));
    }
    let grasp = q
        .grasp_type
        .as_deref()
        .map(GraspFilter::parse)
        .transpose()?;
    if q.phase.is_none() && (q.phase_min_s.is_some() || q.phase_max_s.is_some()) {
        return Err(StoreError::InvalidQuery(
            "phase_min_s and phase_max_s need phase (the phase name)".into(),
        ));
    }
    let real = q.sort.field != SortField::Id;
    let after = match &q.cursor {
        Some(c) => Some(decode_cursor(&q.sort.tag(), real, c)?),
        None => None,
    };
    Ok(SkillFilter {
        object_shape: q.object_shape,
        mass_min: q.mass_min,
        mass_max: q.mass_max,
        mu_min: q.mu_min,
        mu_max: q.mu_max,
        contact_count: q.contact_count,
        contact_model: q.contact_model,
        grasp,
        min_quality: q.min_quality,
        phase: q.phase.map(|phase| PhaseFilter {
            phase,
            min_s: q.phase_min_s,
            max_s: q.phase_max_s,
        }),
        sort: q.sort,
        after,
        fetch: i64::from(q.limit) + 1,
    })
}

/// A validated session query.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SessionFilter<'a> {
    /// Scenario name equals.
    pub scenario: Option<&'a str>,
    /// Hand name equals.
    pub hand: Option<&'a str>,
    /// Object shape equals.
    pub object_shape: Option<ObjectShape>,
    /// Newest (highest id) first.
    pub newest_first: bool,
    /// Only ids after this one (in the query's order).
    pub after: Option<i64>,
    /// Rows to fetch: the page size plus one, to see whether more follow.
    pub fetch: i64,
}

/// The cursor tag of a session query's order. Ascending pages keep the tag they always had,
/// so their cursors stay valid.
pub(crate) fn session_tag(newest_first: bool) -> &'static str {
    if newest_first {
        "sessions-desc"
    } else {
        "sessions"
    }
}

/// Validates `q` into the typed parts of its query: `limit` in `1..=max_limit`, a cursor of
/// the same order.
pub(crate) fn session_filter(
    q: &SessionQuery,
    max_limit: u32,
) -> Result<SessionFilter<'_>, StoreError> {
    let limit = q.limit;
    if limit == 0 || limit > max_limit {
        return Err(StoreError::InvalidQuery(format!(
            "limit {limit} is outside 1..={max_limit}"
        )));
    }
    let after = match &q.cursor {
        Some(c) => match decode_cursor(session_tag(q.newest_first), false, c)? {
            After::Int(id) => Some(id),
            After::Real(..) => return Err(StoreError::BadCursor),
        },
        None => None,
    };
    Ok(SessionFilter {
        scenario: q.scenario.as_deref(),
        hand: q.hand.as_deref(),
        object_shape: q.object_shape,
        newest_first: q.newest_first,
        after,
        fetch: i64::from(limit) + 1,
    })
}

/// The cursor pointing after `skill` under `sort`.
pub(crate) fn cursor_after(sort: SortKey, skill: &super::types::SkillRecord) -> String {
    let after = match sort.field {
        SortField::Id => After::Int(skill.id),
        SortField::Quality => After::Real(skill.quality, skill.id),
        SortField::Mass => After::Real(skill.object_mass, skill.id),
        SortField::Duration => After::Real(skill.duration_s, skill.id),
    };
    encode_cursor(&sort.tag(), after)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cursors_round_trip_and_reject_other_sorts() {
        let c = encode_cursor("quality:desc", After::Real(0.25, 7));
        assert_eq!(
            decode_cursor("quality:desc", true, &c).unwrap(),
            After::Real(0.25, 7)
        );
        assert!(matches!(
            decode_cursor("mass:desc", true, &c),
            Err(StoreError::BadCursor)
        ));
        let c = encode_cursor("id:asc", After::Int(42));
        assert_eq!(decode_cursor("id:asc", false, &c).unwrap(), After::Int(42));
        assert!(matches!(
            decode_cursor("id:asc", false, "zz"),
            Err(StoreError::BadCursor)
        ));
    }

    #[test]
    fn sort_keys_parse_from_their_short_forms() {
        assert_eq!(
            "-quality".parse::<SortKey>().unwrap(),
            SortKey::new(SortField::Quality, SortOrder::Desc)
        );
        assert_eq!(
            "mass:asc".parse::<SortKey>().unwrap(),
            SortKey::new(SortField::Mass, SortOrder::Asc)
        );
        assert!("colour".parse::<SortKey>().is_err());
    }
}
