//! `cargo xtask tx-compare FIRMWARE.log HOST.log`: the firmware's output frames against host
//! replay's, frame by frame.
//!
//! Every frame must be byte-identical, timestamps included, with one exception: the stack
//! high-water mark in NODE_STATUS page 4, which only the firmware can measure (host replay
//! sends "not available"). For those frames the firmware's message, with its stack field
//! replaced by the host's, must re-encode to exactly the host's frame: every other bit is
//! still compared. The command also checks that the firmware did report its stack.
use std::path::Path;

use anyhow::{bail, Context, Result};
use catmodel::can::candump::parse_line;
use catmodel::can::{CanId, NodeStatus, TimedFrame};

/// NODE_STATUS, standard ID 0x3F0 (catmodel.dbc).
const NODE_STATUS_ID: u16 = 0x3F0;

fn read(path: &Path) -> Result<Vec<(String, TimedFrame)>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    text.lines()
        .enumerate()
        .map(|(i, line)| {
            let frame = parse_line(line)
                .map_err(|e| anyhow::anyhow!("{}:{}: {e:?}", path.display(), i + 1))?;
            Ok((line.to_string(), frame))
        })
        .collect()
}

/// The stack field of a NODE_STATUS page 4 frame, if `frame` is one.
fn stack_page(frame: &TimedFrame) -> Option<(NodeStatus, u8)> {
    if frame.frame.id != CanId::Standard(NODE_STATUS_ID) {
        return None;
    }
    match NodeStatus::decode(&frame.frame) {
        Ok((status @ NodeStatus::Ages { .. }, counter)) => Some((status, counter)),
        _ => None,
    }
}

/// What the comparison found.
#[derive(Debug, Default, PartialEq)]
pub struct Comparison {
    pub frames: usize,
    /// Page-4 frames compared with the host's stack field substituted.
    pub stack_pages: usize,
    /// Deepest stack the firmware reported, bytes.
    pub deepest_reported: Option<u32>,
}

fn compare(firmware: &[(String, TimedFrame)], host: &[(String, TimedFrame)]) -> Result<Comparison> {
    if firmware.len() != host.len() {
        bail!(
            "{} frames from the firmware, {} from host replay",
            firmware.len(),
            host.len()
        );
    }
    let mut out = Comparison {
        frames: firmware.len(),
        ..Comparison::default()
    };
    for (i, ((fw_line, fw), (host_line, h))) in firmware.iter().zip(host).enumerate() {
        if fw_line == host_line {
            continue;
        }
        let same = match (stack_page(fw), stack_page(h)) {
            (
                Some((
                    NodeStatus::Ages {
                        ages_10ms,
                        stack_high_water_bytes,
                    },
                    counter,
                )),
                Some((
                    NodeStatus::Ages {
                        stack_high_water_bytes: host_stack,
                        ..
                    },
                    _,
                )),
            ) if fw.t_us == h.t_us => {
                out.stack_pages += 1;
                out.deepest_reported = out.deepest_reported.max(stack_high_water_bytes);
                let substituted = NodeStatus::Ages {
                    ages_10ms,
                    stack_high_water_bytes: host_stack,
                };
                substituted.encode(counter) == h.frame
            }
            _ => false,
        };
        if !same {
            bail!(
                "frame {} differs:\n  firmware: {fw_line}\n  host:     {host_line}",
                i + 1
            );
        }
    }
    Ok(out)
}

/// Compares two candump files (see the module doc).
pub fn compare_files(firmware: &Path, host: &Path) -> Result<Comparison> {
    compare(&read(firmware)?, &read(host)?)
}

pub fn tx_compare(args: &[String]) -> Result<()> {
    let [firmware, host] = args else {
        bail!("usage: cargo xtask tx-compare FIRMWARE.log HOST.log");
    };
    let result = compare_files(Path::new(firmware), Path::new(host))?;
    let Some(deepest) = result.deepest_reported else {
        bail!("the firmware never reported its stack high-water mark in NODE_STATUS page 4");
    };
    println!(
        "tx-compare: {} frames identical to host replay ({} status page-4 frames differ only by \
         the firmware's stack high-water mark, deepest reported {deepest} B)",
        result.frames, result.stack_pages
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use catmodel::can::candump::format_line;

    fn line(frame: &TimedFrame) -> (String, TimedFrame) {
        let mut text = String::new();
        format_line(frame, "can0", &mut text).unwrap();
        (text, *frame)
    }

    fn page4(stack: Option<u32>, age: u8) -> (String, TimedFrame) {
        let status = NodeStatus::Ages {
            ages_10ms: [1, 2, 3, age],
            stack_high_water_bytes: stack,
        };
        line(&TimedFrame {
            t_us: 40_000,
            frame: status.encode(5),
        })
    }

    #[test]
    fn only_the_stack_field_may_differ() {
        let host = vec![page4(None, 4)];
        let result = compare(&[page4(Some(7900), 4)], &host).unwrap();
        assert_eq!(result.stack_pages, 1);
        assert_eq!(result.deepest_reported, Some(7900));
        // Any other difference in the same frame is caught.
        assert!(compare(&[page4(Some(7900), 9)], &host).is_err());
        // Identical files: nothing substituted, nothing reported.
        let same = compare(&host, &host).unwrap();
        assert_eq!(
            (same.frames, same.stack_pages, same.deepest_reported),
            (1, 0, None)
        );
        // Different lengths.
        assert!(compare(&[], &host).is_err());
    }
}
