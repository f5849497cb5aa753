//! Every frame decoder on arbitrary frames: never panics; whatever a decoder accepts, encoding
//! it again (with the same counter or source) decodes to the same message.
#![no_main]
use catmodel::can::codec::{
    decode_input, decode_planner, ControlCommand, GnssCogSog, GnssPosition, LocalOrigin,
    NodeStatus, Obstacle, PathHeader, PathLimits, PathPoint, PedalReport, Prediction, SpeedReport,
    StateMotion, StatePosition, SteeringReport,
};
use catmodel::can::spec::N2K_DEFAULT_SOURCE;
use catmodel_fuzz::RawFrame;
use libfuzzer_sys::fuzz_target;

/// `decode(encode(m, c)) == (m, c)` for an accepted `(m, c)`.
macro_rules! roundtrip {
    ($ty:ty, $frame:expr) => {
        if let Ok((m, c)) = <$ty>::decode($frame) {
            let again = <$ty>::decode(&m.encode(c)).expect("re-encoded frame decodes");
            assert_eq!(again, (m, c));
        }
    };
}

fuzz_target!(|input: (RawFrame, u8)| {
    let (raw, source) = input;
    let f = raw.frame();
    let _ = decode_input(&f, source);
    let _ = decode_input(&f, N2K_DEFAULT_SOURCE);
    roundtrip!(SteeringReport, &f);
    roundtrip!(SpeedReport, &f);
    roundtrip!(PedalReport, &f);
    roundtrip!(StatePosition, &f);
    roundtrip!(StateMotion, &f);
    roundtrip!(ControlCommand, &f);
    let _ = decode_planner(&f);
    roundtrip!(PathHeader, &f);
    roundtrip!(PathPoint, &f);
    roundtrip!(PathLimits, &f);
    roundtrip!(Obstacle, &f);
    roundtrip!(LocalOrigin, &f);
    roundtrip!(Prediction, &f);
    roundtrip!(NodeStatus, &f);
    if let Ok(m) = GnssPosition::decode(&f, source) {
        assert_eq!(
            GnssPosition::decode(&m.encode(source), source).ok(),
            Some(m)
        );
    }
    if let Ok(m) = GnssCogSog::decode(&f, source) {
        assert_eq!(GnssCogSog::decode(&m.encode(source), source).ok(), Some(m));
    }
});
