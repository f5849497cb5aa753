//! The candump line parser on arbitrary text: never panics; whatever it accepts formats back to
//! a line that parses to the same frame (the parser and the formatter agree).
#![no_main]
use catmodel::can::candump::{format_line, parse_line};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = core::str::from_utf8(data) else {
        return;
    };
    for line in text.lines() {
        if let Ok(frame) = parse_line(line) {
            let mut out = String::new();
            format_line(&frame, "can0", &mut out).expect("formatting into a String");
            let again = parse_line(&out).expect("a formatted frame parses");
            assert_eq!(again, frame, "{line:?} -> {out:?}");
        }
    }
});
