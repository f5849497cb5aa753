//! The log and truth CSV readers on arbitrary bytes: never panic; an error always names a line
//! inside the file; accepted rows are finite, within LOG_RANGES and strictly increasing in time (lines
//! with equal time are merged into one row).
#![no_main]
use catmodel_host::logcsv::{parse_log, parse_truth, LOG_RANGES};
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
                let cells = r.cells();
                for (v, range) in cells.iter().zip(&LOG_RANGES) {
                    if let Some(v) = v {
                        assert!(
                            v.is_finite() && *v >= range.min && *v <= range.max,
                            "{}: {r:?}",
                            range.column
                        );
                    }
                }
            }
        }
        Err(e) => assert!(e.line <= lines.max(1), "line {} of {lines}: {e}", e.line),
    }
    if let Err(e) = parse_truth(text, path) {
        assert!(e.line <= lines.max(1), "line {} of {lines}: {e}", e.line);
    }
});
