//! The tick's structure (`catmodel::node::stage::TICK_STAGES`, the first factor of the
//! worst-case bound) against the code: a probe counts how often each stage runs in every tick
//! of a drive that pushes every count to its limit (more frames than the cap, GNSS at three
//! times the receiver's rate, gaps of every length, jumps beyond the gate), and no stage may
//! ever run more often than its row says, nor a tick run stages of two branches (a tick that
//! loads a long path does not also plan). The second factor, each stage's most expensive run,
//! is measured in QEMU (`cargo xtask bench-target`, docs/firmware.md "Worst-case tick").
use catmodel::can::codec::{LocalOrigin, PathHeader, PathLimits, PathPoint, SteeringReport};
use catmodel::can::{CanFrame, TimedFrame};
use catmodel::geodesy::{Enu, LocalFrame};
use catmodel::node::{
    due_ticks, first_tick_us, Branch, BranchTaken, PlatformStats, Stage, StageProbe, Tick,
    TxFrames, TICK_STAGES,
};
use catmodel_host_tests::bus::{
    config, curvature, drive, rear_axle, Kind, Labelled, ORIGIN, START_US,
};

/// Runs per stage (indexed as `TICK_STAGES`) in the current tick, the most in any tick, and
/// every tick's runs.
#[derive(Default)]
struct Counting {
    this_tick: [u32; TICK_STAGES.len()],
    most: [u32; TICK_STAGES.len()],
    /// The runs of every tick so far.
    ticks: Vec<[u32; TICK_STAGES.len()]>,
    /// The branch the current tick took.
    branch: BranchTaken,
    /// A stage that ran beside a stage of another branch, and the tick.
    mixed: Option<(Stage, usize)>,
    /// A stage reported that has no row.
    unknown: Option<Stage>,
}

impl StageProbe for Counting {
    fn lap(&mut self, stage: Stage) {
        match TICK_STAGES.iter().position(|row| row.stage == stage) {
            Some(i) => self.this_tick[i] += 1,
            None => self.unknown = Some(stage),
        }
        if !self.branch.enter(stage) {
            self.mixed = Some((stage, self.ticks.len()));
        }
    }
}

impl Counting {
    fn end_tick(&mut self) {
        for (most, n) in self.most.iter_mut().zip(self.this_tick) {
            *most = (*most).max(n);
        }
        self.ticks.push(self.this_tick);
        self.this_tick = Default::default();
        self.branch = BranchTaken::new();
    }

    /// Ticks in which `stage` ran.
    fn ticks_with(&self, stage: Stage) -> Vec<usize> {
        let i = TICK_STAGES.iter().position(|r| r.stage == stage).unwrap();
        (0..self.ticks.len())
            .filter(|&t| self.ticks[t][i] > 0)
            .collect()
    }
}

/// The heavy drive's speed, m/s, and steering, %.
const HEAVY_SPEED_MPS: f32 = 12.0;
const HEAVY_STEER_PCT: f32 = 30.0;
/// The planner's map origin in the heavy drive (LOCAL_ORIGIN, 1e-7 deg): the frame its paths
/// are in.
const PLANNER_ORIGIN: (i32, i32) = (322_310_000, -1_109_500_000);

/// A 12 m/s drive in a turn, with every count pushed to its limit.
fn heavy_drive() -> Vec<TimedFrame> {
    let base = drive(HEAVY_SPEED_MPS, HEAVY_STEER_PCT, 10.0);
    let mut frames: Vec<TimedFrame> = Vec::new();
    let mut fix_index = 0u64;
    let mut bad = SteeringReport {
        steer_pct: Some(0.0),
    }
    .encode(0);
    bad.data[7] ^= 0x3C;
    for Labelled { kind, frame } in base {
        let t_s = (frame.t_us - START_US) as f64 * 1e-6;
        if kind != Kind::Gnss {
            frames.push(frame);
            continue;
        }
        fix_index += 1;
        // Gaps of 1, 2, 3 and 6 fixes, then a 0.5 s outage; and a stretch 30 m off (beyond
        // the gate for longer than the node waits before following it).
        let gap =
            matches!(fix_index % 97, 10 | 30 | 31 | 50..=52 | 70..=75) || (6.0..6.5).contains(&t_s);
        if gap {
            continue;
        }
        let mut fix = frame;
        if (7.0..8.5).contains(&t_s) {
            // 4096e-7 deg of longitude further: about 38 m east.
            fix.frame.data[5] = fix.frame.data[5].wrapping_add(0x10);
        }
        // Every third fix received 10 ms late, with the next: three fixes in a tick (the cap)
        // now and then, at the receiver's rate. Not faster: the node does not use fixes at 1.4
        // times the declared rate (`gnss::CROWDED_TENTHS`), and the three times this drive sent
        // before (each fix again 3 and 6 ms later) are another receiver's.
        if fix_index.is_multiple_of(3) {
            fix.t_us += 10_000;
        }
        frames.push(fix);
        // Every 2 s the planner moves the map origin (both pages of LOCAL_ORIGIN, twice in
        // the same tick: the node applies the last one, once).
        if fix_index % 200 == 100 {
            for (k, lat_e7) in [(0u8, 322_300_000), (2, PLANNER_ORIGIN.0)] {
                for (c, page) in [
                    (k, LocalOrigin::Latitude { lat_e7 }),
                    (
                        k + 1,
                        LocalOrigin::Longitude {
                            lon_e7: PLANNER_ORIGIN.1,
                        },
                    ),
                ] {
                    frames.push(TimedFrame {
                        t_us: fix.t_us,
                        frame: page.encode(c),
                    });
                }
            }
        }
        // Every 0.5 s a burst of 30 frames the node must decode and reject.
        if fix_index.is_multiple_of(50) {
            for _ in 0..30 {
                frames.push(TimedFrame {
                    t_us: fix.t_us,
                    frame: bad,
                });
            }
        }
    }
    frames.sort_by_key(|f| f.t_us);
    planner_bursts(&mut frames);
    frames
}

/// The tick (1-based, as in [`planner_bursts`]) that completes the last long path.
const PATH_AGAIN_TICK: u64 = 230;

/// Paths completing at the most one tick allows: a 6-point path begun two ticks earlier and
/// two 2-point paths in one tick (one long, two short completions), then a short path begun a
/// tick earlier and two more (three short completions); a 5-point path at tick 215, after the
/// heading has settled (the controllers count its settling from the first path: 60 ticks at
/// 100 Hz); then, while the controller plans on it, a 6-point path again (a tick that loads a
/// long path with a plan to move on). Each tick's planner frames come first in it, so the cap leaves them all to the node.
/// Every path lies on the car's own circle, from a metre behind where it is when the path's
/// first frame goes out, 1 m apart: the car is on it (a car off its path is not planned for).
fn planner_bursts(frames: &mut Vec<TimedFrame>) {
    let t0 = first_tick_us(frames[0].t_us);
    let origin = LocalFrame::new(ORIGIN.0, ORIGIN.1).unwrap();
    let planner = LocalFrame::new(PLANNER_ORIGIN.0, PLANNER_ORIGIN.1).unwrap();
    let kappa = curvature(HEAVY_SPEED_MPS, HEAVY_STEER_PCT);
    let v = f64::from(HEAVY_SPEED_MPS);
    // The rear axle `along_m` metres of arc from where it is at `tick`, in the planner's frame.
    let on_circle = |tick: u64, along_m: f64| -> (f32, f32) {
        let t_s = (t0 + (tick - 1) * 20_000 - START_US) as f64 * 1e-6 + along_m / v;
        let (east, north, _) = rear_axle(v, kappa, t_s);
        let (lat, lon) = origin.from_local(Enu {
            east_m: east as f32,
            north_m: north as f32,
        });
        let enu = planner
            .to_local((lat * 1e7).round() as i32, (lon * 1e7).round() as i32)
            .unwrap();
        (enu.east_m, enu.north_m)
    };
    let mut counters = [0u8; 3];
    let mut next = |slot: usize| {
        let c = counters[slot];
        counters[slot] = (c + 1) & 0x0F;
        c
    };
    let mut path = |path_id: u8, points: usize, tick: u64| -> Vec<CanFrame> {
        let mut out = vec![PathHeader {
            path_id,
            count: points as u16,
        }
        .encode(next(0))];
        for i in 0..points {
            let (east_m, north_m) = on_circle(tick, i as f64 - 1.0);
            out.push(
                PathPoint {
                    path_id,
                    index: i as u8,
                    east_m,
                    north_m,
                }
                .encode(next(1)),
            );
        }
        for i in 0..points {
            out.push(
                PathLimits {
                    path_id,
                    index: i as u8,
                    speed_mps: 5.0,
                    left_m: 3.0,
                    right_m: 3.0,
                }
                .encode(next(2)),
            );
        }
        out
    };
    let long = path(1, 6, 148);
    let (a, b) = (path(2, 2, 150), path(3, 2, 150));
    let carried = path(4, 2, 159);
    let (c, d) = (path(5, 2, 160), path(6, 2, 160));
    let fresh = path(8, 5, 215);
    let again = path(7, 6, PATH_AGAIN_TICK - 1);
    let ticks: [(u64, Vec<CanFrame>); 8] = [
        (148, long[..7].to_vec()),
        (149, long[7..12].to_vec()),
        (150, [&long[12..], &a[..], &b[..]].concat()),
        (159, carried[..4].to_vec()),
        (160, [&carried[4..], &c[..], &d[..]].concat()),
        (215, fresh),
        (PATH_AGAIN_TICK - 1, again[..7].to_vec()),
        (PATH_AGAIN_TICK, again[7..].to_vec()),
    ];
    for (k, burst) in ticks {
        assert!(burst.len() <= catmodel::node::MAX_RX_FRAMES_PER_TICK);
        let start = t0 + (k - 1) * 20_000;
        for (i, frame) in burst.into_iter().enumerate() {
            frames.push(TimedFrame {
                t_us: start + 1 + i as u64,
                frame,
            });
        }
    }
    frames.sort_by_key(|f| f.t_us);
}

/// Steps a probed and a plain node over `frames` (every due frame handed to the tick: more
/// than the cap when there are); returns the counts and whether both sent the same frames.
fn run(frames: &[TimedFrame]) -> (Counting, bool) {
    let mut probed = catmodel_host::new_node(config());
    let mut plain = catmodel_host::new_node(config());
    let mut counting = Counting::default();
    let mut same = true;
    for (now_us, due) in due_ticks(frames) {
        let tick = Tick {
            now_us,
            platform: PlatformStats::default(),
        };
        let (mut a, mut b) = (TxFrames::new(), TxFrames::new());
        let ea = probed.step_probed(&tick, &frames[due.clone()], &mut a, &mut counting);
        let eb = plain.step(&tick, &frames[due], &mut b);
        same &= a == b && ea == eb;
        counting.end_tick();
    }
    (counting, same)
}

#[test]
fn every_stage_has_one_row() {
    // The match is exhaustive: a new stage does not compile here until it is listed.
    let listed = |stage: Stage| match stage {
        Stage::Advance
        | Stage::Frame
        | Stage::GnssOrigin
        | Stage::GnssFixCheck
        | Stage::GnssFill
        | Stage::GnssRestart
        | Stage::GnssFixFilter
        | Stage::Models
        | Stage::Origin
        | Stage::PathComplete
        | Stage::PathCompleteShort
        | Stage::Estimate
        | Stage::DriveReference
        | Stage::MpcSolve
        | Stage::DriveCoast
        | Stage::Drive
        | Stage::Predict
        | Stage::Publish => true,
    };
    let all = [
        Stage::Advance,
        Stage::Frame,
        Stage::PathComplete,
        Stage::PathCompleteShort,
        Stage::Origin,
        Stage::GnssOrigin,
        Stage::GnssFixCheck,
        Stage::GnssFill,
        Stage::GnssRestart,
        Stage::GnssFixFilter,
        Stage::Models,
        Stage::Estimate,
        Stage::DriveReference,
        Stage::MpcSolve,
        Stage::DriveCoast,
        Stage::Drive,
        Stage::Predict,
        Stage::Publish,
    ];
    for stage in all {
        assert!(listed(stage));
        let rows = TICK_STAGES.iter().filter(|r| r.stage == stage).count();
        assert_eq!(rows, 1, "{stage:?}");
    }
    assert_eq!(TICK_STAGES.len(), all.len());
    let mut keys: Vec<&str> = TICK_STAGES.iter().map(|r| r.key).collect();
    keys.sort_unstable();
    keys.dedup();
    assert_eq!(keys.len(), TICK_STAGES.len(), "keys are unique");
}

#[test]
fn no_stage_runs_more_often_than_its_row_and_the_drive_reaches_every_limit() {
    let frames = heavy_drive();
    let (counting, same) = run(&frames);
    assert_eq!(counting.unknown, None);
    assert_eq!(counting.mixed, None, "a tick ran stages of two branches");
    for (row, most) in TICK_STAGES.iter().zip(counting.most) {
        assert!(
            most <= row.max_per_tick,
            "{}: {most} runs in one tick, its row allows {}",
            row.key,
            row.max_per_tick
        );
        // The drive pushes every stage to its limit, so the check above is not vacuous.
        assert_eq!(
            most, row.max_per_tick,
            "{} never reached its limit",
            row.key
        );
    }
    assert!(same, "the probed step sent other frames than the plain one");
}

#[test]
fn the_probed_step_is_the_step() {
    // Plain drives too: what the probe sees is exactly the tick that runs.
    for frames in [
        drive(5.0, -20.0, 4.0),
        drive(25.0, 60.0, 4.0),
        drive(0.0, 0.0, 2.0),
    ] {
        let frames: Vec<TimedFrame> = frames.iter().map(|l| l.frame).collect();
        let (_, same) = run(&frames);
        assert!(same);
    }
    // And a tick given nothing but frames the node cannot use.
    let junk = vec![
        TimedFrame {
            t_us: START_US,
            frame: CanFrame::new(catmodel::can::CanId::Standard(0x7FF), &[1, 2]).unwrap(),
        };
        40
    ];
    let (counting, same) = run(&junk);
    assert!(same);
    let frame_row = TICK_STAGES
        .iter()
        .position(|r| r.stage == Stage::Frame)
        .unwrap();
    assert_eq!(
        counting.most[frame_row],
        catmodel::node::MAX_RX_FRAMES_PER_TICK as u32
    );
}

#[test]
fn a_tick_that_loads_a_long_path_does_not_plan_and_the_next_one_does() {
    let frames = heavy_drive();
    let (counting, _) = run(&frames);
    assert_eq!(counting.mixed, None);
    let loads = counting.ticks_with(Stage::PathComplete);
    let plans = counting.ticks_with(Stage::MpcSolve);
    let coasts = counting.ticks_with(Stage::DriveCoast);
    // Both long paths; the first arrives before any plan (nothing to move on: a hold), the
    // second while the controller plans (it moves the plan on).
    assert_eq!(loads.len(), 2, "{loads:?}");
    assert_eq!(coasts, loads[1..].to_vec());
    assert!(
        plans.contains(&(loads[1] - 1)),
        "a plan before the second load"
    );
    for &load in &loads {
        assert!(
            !plans.contains(&load),
            "tick {load} loaded a long path and planned"
        );
    }
    // After the first load the controller waits for the heading to settle (counted from the
    // first path); after the second it plans in the very next tick.
    for load in &loads[1..] {
        assert!(
            plans.contains(&(load + 1)),
            "no plan in the tick after {load}"
        );
    }
    // The rows say so: the loading stages are one branch, the plan's another.
    let branch = |stage: Stage| {
        TICK_STAGES
            .iter()
            .find(|r| r.stage == stage)
            .unwrap()
            .branch
    };
    assert_eq!(branch(Stage::PathComplete), Branch::PathLoad);
    assert_eq!(branch(Stage::DriveCoast), Branch::PathLoad);
    assert_eq!(branch(Stage::MpcSolve), Branch::Plan);
    assert_eq!(branch(Stage::DriveReference), Branch::Plan);
    // What may run beside a plan is common: short paths, the origin.
    assert_eq!(branch(Stage::PathCompleteShort), Branch::Common);
    assert_eq!(branch(Stage::Origin), Branch::Common);
}

/// Runs a plain node over `frames` with a counting probe, each frame handed to the first tick
/// at or after its release time (later than its timestamp: a backlog the receive queue held
/// back); returns the counts and, per tick, the node's `gnss_gate_rejects` after it.
fn run_released(frames: &[(u64, TimedFrame)]) -> (Counting, Vec<u32>) {
    let mut node = catmodel_host::new_node(config());
    let mut counting = Counting::default();
    let mut rejects = Vec::new();
    let mut now = first_tick_us(frames[0].0);
    let mut next = 0;
    while next < frames.len() {
        let start = next;
        while next < frames.len() && frames[next].0 <= now {
            next += 1;
        }
        let due: Vec<TimedFrame> = frames[start..next].iter().map(|(_, f)| *f).collect();
        let tick = Tick {
            now_us: now,
            platform: PlatformStats::default(),
        };
        let mut tx = TxFrames::new();
        node.step_probed(&tick, &due, &mut tx, &mut counting);
        counting.end_tick();
        rejects.push(node.counters().gnss_gate_rejects);
        now += 20_000;
    }
    (counting, rejects)
}

#[test]
fn a_tick_fills_missing_fixes_or_restarts_the_lowpass_not_both() {
    // The tick's bound counts the dearer of filling and restarting (Exclusive::GnssGap), so no
    // tick may do both. A backlog makes a tick want both: the receive queue held fix A (one
    // fix after a skipped one: a fill) back to the tick of fix B, 40 ms after A (three missing:
    // a restart). The 100 Hz receiver's fixes between them are lost.
    let base = drive(8.0, 10.0, 6.0);
    let gnss: Vec<u64> = base
        .iter()
        .filter(|l| l.kind == Kind::Gnss)
        .map(|l| l.frame.t_us)
        .collect();
    let p = gnss
        .iter()
        .position(|&t| t >= START_US + 3_000_000)
        .unwrap();
    let (a, b) = (gnss[p + 2], gnss[p + 6]);
    let mut frames: Vec<(u64, TimedFrame)> = Vec::new();
    for Labelled { kind, frame } in base {
        let t = frame.t_us;
        if kind == Kind::Gnss && t > gnss[p] && t < b && t != a {
            continue;
        }
        let release = if t == a && kind == Kind::Gnss { b } else { t };
        frames.push((release, frame));
    }
    frames.sort_by_key(|(r, f)| (*r, f.t_us));
    let (counting, rejects) = run_released(&frames);
    assert_eq!(counting.mixed, None, "a tick filled and restarted");
    let fills = counting.ticks_with(Stage::GnssFill);
    let t = *fills.first().expect("fix A fills the skipped fix");
    // Fix B and the fix 10 ms after it (the tick's other fix, as far from A) were not placed
    // in A's tick: counted, not dropped; no restart in that tick.
    assert_eq!(
        rejects[t] - rejects[t - 1],
        2,
        "B and the next fix are counted"
    );
    // The next tick restarts the lowpass on the track from A.
    assert_eq!(counting.ticks_with(Stage::GnssRestart), vec![t + 1]);
}
