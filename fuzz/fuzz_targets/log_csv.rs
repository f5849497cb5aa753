//! The log and truth CSV readers on arbitrary bytes: never panic; an error always names a line
//! inside the file; accepted rows are finite, in range and strictly increasing in time (lines
//! with equal time are merged into one row).
#![no_main]
use catmodel_host::logcsv::{parse_log, parse_truth};
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = core::str::from_utf8(data) else {
        return;
    };
    let lines = text.lines().count();
    let path = Path::new("fuzz.csv");
    match parse_log(text, path) {
        Ok(log) => {
            let rows = log.rows;
            for w in rows.windows(2) {
                assert!(
                    w[1].t > w[0].t,
                    "time not increasing: {} then {}",
                    w[0].t,
                    w[1].t
                );
            }
            for r in &rows {
                assert!(r.t.is_finite());
                for v in [r.vel, r.input_vel, r.accel, r.steer, r.brake, r.lat, r.lon]
                    .into_iter()
                    .flatten()
                {
                    assert!(v.is_finite(), "{r:?}");
                }
            }
        }
        Err(e) => assert!(e.line <= lines.max(1), "line {} of {lines}: {e}", e.line),
    }
    if let Err(e) = parse_truth(text, path) {
        assert!(e.line <= lines.max(1), "line {} of {lines}: {e}", e.line);
    }
});
