//! [`MessageCheck`] of the Foxglove types against prost, on real messages of a simulated
//! session, damaged ones and any bytes.

use super::super::MessageCheck;
use proptest::prelude::*;
use prost::Message;

/// The checks of the three Foxglove types, as the reader makes them.
pub(super) fn foxglove_checks() -> &'static [MessageCheck; 3] {
    use foxglove::messages as fg;
    use foxglove::Encode;
    static CHECKS: std::sync::OnceLock<[MessageCheck; 3]> = std::sync::OnceLock::new();
    CHECKS.get_or_init(|| {
        let make = |s: Option<foxglove::Schema>| {
            let s = s.unwrap();
            MessageCheck::new(&s.data, &s.name).unwrap()
        };
        [
            make(fg::FrameTransforms::get_schema()),
            make(fg::SceneUpdate::get_schema()),
            make(fg::JointStates::get_schema()),
        ]
    })
}

/// Real Foxglove messages of a short simulated session: `/tf`, `/scene` and `/hand`
/// (scene updates), `/joint_states`, with which of [`foxglove_checks`] reads each.
fn foxglove_samples() -> &'static Vec<(usize, Vec<u8>)> {
    static SAMPLES: std::sync::OnceLock<Vec<(usize, Vec<u8>)>> = std::sync::OnceLock::new();
    SAMPLES.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.mcap");
        let scenario = dfs_core::scenario::Scenario::builtin("cylinder-power-grasp", 1).unwrap();
        crate::session::record_simulation(&scenario, Some(3.0), &path, |_, _| {}).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let mut samples = Vec::new();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            let which = match m.channel.topic.as_str() {
                "/tf" => 0,
                "/scene" | "/hand" => 1,
                "/joint_states" => 2,
                _ => continue,
            };
            // A few of each (the scene's change as the grasp goes).
            if samples.iter().filter(|(w, _)| *w == which).count() < 40 || m.sequence % 97 == 0 {
                samples.push((which, m.data.to_vec()));
            }
        }
        assert!((0..3).all(|w| samples.iter().any(|(s, _)| *s == w)));
        samples
    })
}

/// prost's verdict on `bytes` as Foxglove type `which`.
fn prost_accepts(which: usize, bytes: &[u8]) -> bool {
    use foxglove::messages as fg;
    match which {
        0 => fg::FrameTransforms::decode(bytes).is_ok(),
        1 => fg::SceneUpdate::decode(bytes).is_ok(),
        _ => fg::JointStates::decode(bytes).is_ok(),
    }
}

#[test]
fn real_foxglove_messages_pass_their_check_and_fail_the_others_where_prost_does() {
    let checks = foxglove_checks();
    for (which, bytes) in foxglove_samples() {
        assert!(checks[*which].check(bytes).is_ok());
        for other in 0..3 {
            assert_eq!(
                checks[other].check(bytes).is_ok(),
                prost_accepts(other, bytes),
                "type {other} on a message of type {which}"
            );
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]

    #[test]
    fn foxglove_checks_accept_and_refuse_what_prost_does(
        sample in any::<prop::sample::Index>(),
        edits in proptest::collection::vec((0u8..5, any::<prop::sample::Index>(), any::<u8>()), 1..4),
    ) {
        // A real message damaged: bits flipped, bytes set, inserted or removed, cut short.
        let samples = foxglove_samples();
        let (which, original) = &samples[sample.index(samples.len())];
        let mut bytes = original.clone();
        for (kind, at, byte) in edits {
            let i = at.index(bytes.len() + 1);
            match kind {
                0 if i < bytes.len() => bytes[i] ^= 1 << (byte % 8),
                1 if i < bytes.len() => bytes[i] = byte,
                2 => bytes.insert(i, byte),
                3 if i < bytes.len() => { bytes.remove(i); }
                _ => bytes.truncate(i),
            }
        }
        let checks = foxglove_checks();
        for t in [*which, (*which + 1) % 3] {
            prop_assert_eq!(checks[t].check(&bytes).is_ok(), prost_accepts(t, &bytes), "type {} on {:?}", t, bytes);
        }
    }

    #[test]
    fn foxglove_checks_of_any_bytes_agree_with_prost(bytes in proptest::collection::vec(any::<u8>(), 0..96)) {
        let checks = foxglove_checks();
        for t in 0..3 {
            prop_assert_eq!(checks[t].check(&bytes).is_ok(), prost_accepts(t, &bytes), "type {} on {:?}", t, bytes);
        }
    }
}
