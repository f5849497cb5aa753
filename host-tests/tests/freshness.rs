//! Properties of the freshness state machine (`catmodel::can::freshness`): every input is
//! fresh exactly while its newest accepted sample is at most its timeout old, whatever order
//! samples arrive in; ages follow, saturate and never run backwards. Checked against a direct
//! model (the newest time per input, kept in a plain array) over arbitrary streams.
use catmodel::can::freshness::{Freshness, FreshnessConfig, Input, AGE_MAX, AGE_NEVER};
use proptest::prelude::*;

fn input() -> impl Strategy<Value = Input> {
    (0usize..4).prop_map(|i| Input::ALL[i])
}

/// Marks: (input, receive time), times up to ~10 s with clusters so timeouts are crossed often.
fn marks() -> impl Strategy<Value = Vec<(Input, u64)>> {
    proptest::collection::vec((input(), 0u64..10_000_000), 0..60)
}

fn model(marks: &[(Input, u64)]) -> [Option<u64>; 4] {
    let mut last = [None; 4];
    for &(input, t) in marks {
        let slot = &mut last[input.index()];
        *slot = Some(slot.map_or(t, |l: u64| l.max(t)));
    }
    last
}

fn apply(marks: &[(Input, u64)]) -> Freshness {
    let mut f = Freshness::new();
    for &(input, t) in marks {
        f.mark(input, t);
    }
    f
}

proptest! {
    #[test]
    fn fresh_exactly_while_the_newest_sample_is_within_its_timeout(
        marks in marks(),
        now in 0u64..12_000_000,
    ) {
        let cfg = FreshnessConfig::default();
        let f = apply(&marks);
        let last = model(&marks);
        for input in Input::ALL {
            let expected = last[input.index()]
                .is_some_and(|l| now.saturating_sub(l) <= cfg.timeout_us(input));
            prop_assert_eq!(f.is_fresh(&cfg, input, now), expected);
            prop_assert_eq!(f.last_us(input), last[input.index()]);
        }
    }

    #[test]
    fn arrival_order_does_not_matter(mut marks in marks(), seed in any::<u64>()) {
        let forward = apply(&marks);
        // A deterministic shuffle (reverse, then rotate by the seed).
        marks.reverse();
        if !marks.is_empty() {
            let k = (seed as usize) % marks.len();
            marks.rotate_left(k);
        }
        prop_assert_eq!(apply(&marks), forward);
    }

    #[test]
    fn ages_saturate_never_run_backwards_and_say_never(
        marks in marks(),
        now in 0u64..12_000_000,
        later in 0u64..5_000_000,
    ) {
        let f = apply(&marks);
        let last = model(&marks);
        for input in Input::ALL {
            let age = f.age_10ms(input, now);
            let after = f.age_10ms(input, now + later);
            match last[input.index()] {
                None => {
                    prop_assert_eq!(age, AGE_NEVER);
                    prop_assert_eq!(after, AGE_NEVER);
                }
                Some(l) => {
                    let expected = (now.saturating_sub(l) / 10_000).min(u64::from(AGE_MAX));
                    prop_assert_eq!(u64::from(age), expected);
                    prop_assert!(after >= age && after <= AGE_MAX);
                }
            }
        }
    }

    #[test]
    fn a_stale_input_recovers_on_its_first_new_sample_and_not_before(
        input in input(),
        t0 in 0u64..1_000_000,
        gap in 1u64..2_000_000,
    ) {
        let cfg = FreshnessConfig::default();
        let timeout = cfg.timeout_us(input);
        let mut f = Freshness::new();
        prop_assert!(!f.is_fresh(&cfg, input, t0));
        f.mark(input, t0);
        // Fresh for exactly `timeout`, stale after it.
        prop_assert!(f.is_fresh(&cfg, input, t0 + timeout));
        prop_assert!(!f.is_fresh(&cfg, input, t0 + timeout + 1));
        let t1 = t0 + timeout + gap;
        prop_assert!(!f.is_fresh(&cfg, input, t1));
        // An old sample arriving late does not revive it.
        f.mark(input, t0 + 1);
        prop_assert!(!f.is_fresh(&cfg, input, t1));
        f.mark(input, t1);
        prop_assert!(f.is_fresh(&cfg, input, t1));
        // The other inputs are untouched.
        for other in Input::ALL.into_iter().filter(|&o| o != input) {
            prop_assert_eq!(f.last_us(other), None);
        }
    }
}
