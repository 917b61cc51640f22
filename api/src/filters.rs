//! The skill filters, sort and page of a skill query, as one set of named parameters shared by
//! the command line (`icms skills --shape box ...`) and the HTTP API
//! (`GET /api/v1/skills?shape=box&...`), and their translation into the store's
//! [`SkillQuery`]. Names and meanings are the same in both places, and so is the parsing of a
//! shape, contact model or phase (their types' own: `FromStr` for a flag, `Deserialize` for a
//! query string), which refuses a name they do not know, naming the parameter.

use dfs_core::contact::ContactModel;
use dfs_core::scenario::Phase;
use serde::Deserialize;
use services::store::{ObjectShape, SkillQuery, SortKey, StoreError, DEFAULT_LIMIT};

/// Filters, sort and page of a skill query. Every filter is optional; ranges are inclusive.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, clap::Args, utoipa::IntoParams)]
#[serde(default, deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct SkillFilters {
    /// Object shape: sphere, box, cylinder, or unknown (a session stored before sessions had
    /// to name their object).
    #[arg(long)]
    #[param(value_type = Option<String>)]
    pub shape: Option<ObjectShape>,
    /// Least object mass, kg.
    #[arg(long, allow_negative_numbers = true)]
    pub mass_min: Option<f64>,
    /// Largest object mass, kg.
    #[arg(long, allow_negative_numbers = true)]
    pub mass_max: Option<f64>,
    /// Least Coulomb friction coefficient.
    #[arg(long, allow_negative_numbers = true)]
    pub mu_min: Option<f64>,
    /// Largest Coulomb friction coefficient.
    #[arg(long, allow_negative_numbers = true)]
    pub mu_max: Option<f64>,
    /// Number of fingertip contacts.
    #[arg(long, allow_negative_numbers = true)]
    #[param(minimum = 0)]
    pub contacts: Option<i64>,
    /// Contact model: frictionless, point_with_friction or soft_finger.
    #[arg(long)]
    #[param(value_type = Option<String>)]
    pub contact_model: Option<ContactModel>,
    /// Grasp type: precision or power (or a whole label such as precision-2vf).
    #[arg(long)]
    pub grasp_type: Option<String>,
    /// Least Ferrari-Canny grasp quality ε.
    #[arg(long, allow_negative_numbers = true)]
    pub min_quality: Option<f64>,
    /// The skill has a phase of this name (with phase_min_s / phase_max_s: of that duration).
    #[arg(long)]
    #[param(value_type = Option<String>)]
    pub phase: Option<Phase>,
    /// Least duration of `phase`, s (needs `phase`).
    #[arg(long, allow_negative_numbers = true)]
    pub phase_min_s: Option<f64>,
    /// Largest duration of `phase`, s (needs `phase`).
    #[arg(long, allow_negative_numbers = true)]
    pub phase_max_s: Option<f64>,
    /// Sort: id, quality, mass or duration, optionally with `:asc` / `:desc` (or a leading `-`
    /// for descending). Default: id ascending.
    #[arg(long, allow_hyphen_values = true)]
    pub sort: Option<String>,
    /// Page size, 1 to 1000. Default 50.
    #[arg(long, allow_negative_numbers = true)]
    #[param(minimum = 1, maximum = 1000)]
    pub limit: Option<u32>,
    /// `next_cursor` of the previous page, passed back unchanged with the same filters and sort.
    #[arg(long)]
    pub cursor: Option<String>,
}

impl SkillFilters {
    /// The store query these parameters ask for. A malformed sort is
    /// [`StoreError::InvalidQuery`]; the store itself checks ranges, limit and cursor.
    pub fn to_query(&self) -> Result<SkillQuery, StoreError> {
        let sort: SortKey = match &self.sort {
            Some(s) => s.parse()?,
            None => SortKey::default(),
        };
        Ok(SkillQuery {
            object_shape: self.shape,
            mass_min: self.mass_min,
            mass_max: self.mass_max,
            mu_min: self.mu_min,
            mu_max: self.mu_max,
            contact_count: self.contacts,
            contact_model: self.contact_model,
            grasp_type: self.grasp_type.clone(),
            min_quality: self.min_quality,
            phase: self.phase,
            phase_min_s: self.phase_min_s,
            phase_max_s: self.phase_max_s,
            sort,
            limit: self.limit.unwrap_or(DEFAULT_LIMIT),
            cursor: self.cursor.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use services::store::{SortField, SortOrder};

    #[test]
    fn command_line_flags_and_query_string_give_the_same_query() {
        use clap::Parser;
        #[derive(Parser)]
        struct Cli {
            #[command(flatten)]
            f: SkillFilters,
        }
        let cli = Cli::try_parse_from([
            "x",
            "--shape",
            "box",
            "--mass-min",
            "0.1",
            "--contacts",
            "2",
            "--phase",
            "hold",
            "--phase-max-s",
            "2.5",
            "--sort",
            "-quality",
            "--limit",
            "7",
        ])
        .unwrap()
        .f;
        let http: SkillFilters = serde_json::from_value(serde_json::json!({
            "shape": "box", "mass_min": 0.1, "contacts": 2, "phase": "hold",
            "phase_max_s": 2.5, "sort": "-quality", "limit": 7
        }))
        .unwrap();
        assert_eq!(cli, http);
        let q = cli.to_query().unwrap();
        assert_eq!(
            q.object_shape,
            Some(ObjectShape::Known(dfs_core::object::ShapeKind::Box))
        );
        assert_eq!(q.phase, Some(Phase::Hold));
        assert_eq!(q.contact_count, Some(2));
        assert_eq!(q.sort, SortKey::new(SortField::Quality, SortOrder::Desc));
        assert_eq!(q.limit, 7);
    }

    #[test]
    fn defaults_are_id_order_and_fifty_per_page() {
        let q = SkillFilters::default().to_query().unwrap();
        assert_eq!(q, SkillQuery::default());
    }

    #[test]
    fn an_unknown_shape_contact_model_or_phase_is_refused_on_the_command_line_and_in_a_query() {
        use clap::Parser;
        #[derive(Parser, Debug)]
        struct Cli {
            #[command(flatten)]
            f: SkillFilters,
        }
        for (flag, value, message) in [
            (
                "--shape",
                "torus",
                "unknown shape \"torus\"; expected one of sphere, box, cylinder, unknown",
            ),
            (
                "--contact-model",
                "magic",
                "unknown contact model \"magic\"",
            ),
            ("--phase", "juggle", "unknown phase \"juggle\""),
        ] {
            let e = Cli::try_parse_from(["x", flag, value])
                .unwrap_err()
                .to_string();
            assert!(e.contains(flag) && e.contains(message), "{e}");
        }
        for (name, value, message) in [
            ("shape", "Sphere", "unknown shape \"Sphere\""),
            ("contact_model", "magic", "unknown contact model \"magic\""),
            ("phase", "juggle", "unknown phase \"juggle\""),
        ] {
            let e = serde_json::from_value::<SkillFilters>(serde_json::json!({ name: value }))
                .unwrap_err()
                .to_string();
            assert!(e.contains(message), "{e}");
        }
        let q: SkillFilters =
            serde_json::from_value(serde_json::json!({"shape": "unknown"})).unwrap();
        assert_eq!(q.shape, Some(ObjectShape::Unknown));
    }

    #[test]
    fn an_unknown_parameter_or_sort_is_refused() {
        assert!(
            serde_json::from_value::<SkillFilters>(serde_json::json!({"colour": "red"})).is_err()
        );
        let f = SkillFilters {
            sort: Some("colour".into()),
            ..SkillFilters::default()
        };
        assert!(matches!(f.to_query(), Err(StoreError::InvalidQuery(_))));
    }
}
