//! The vision unit (`rtl/vision_unit.v`) against the cycle-accurate model (`soc_model`) and the
//! reference encoder (`vision::runs`), on frames the arena's synthetic camera renders.
//!
//! A program loads the marker class table into the unit, enables it with its interrupt, and for
//! each frame waits (polling the status register for the first, in WFI on the PLIC line after),
//! acknowledges, and sends the whole published header and the ready buffer's words to the
//! console. Both the RTL and the model run it with the same frames streamed into the camera port
//! at the same cycles; every retirement record (each load of a register or run word, with its
//! data) and every console byte must be the same in the same cycle, and the runs must be the
//! reference encoder's.

mod common;

use arena::camera::{CameraConfig, CarPose, SyntheticCamera};
use common::{compare_records, model_events, rtl_events, Prog};
use verilator_tb::isa::{self, reg::*};
use verilator_tb::soc::{irq, map, CameraTiming, Event, Exit, Soc, RAM_BASE};
use vision::colour::MARKER_CLASSES;
use vision::run_window::{ctrl, field, status, HEADER_LEN};
use vision::runs::encode_codes;

/// A frame period at 30 frames per second.
const PERIOD: u64 = 14_745_600 / 30;

/// Emits the word in `reg` as four console bytes, low first (clobbers T2).
fn console_word(p: &mut Prog, reg: u8) {
    p.i(isa::sw(reg, A1, 0));
    for sh in [8, 16, 24] {
        p.i(isa::srli(T2, reg, sh)).i(isa::sw(T2, A1, 0));
    }
}

/// The program: class table, PLIC source 12, unit on; then `frames` times: wait for a frame
/// (the first by polling STATUS, the rest in WFI), acknowledge, dump header and runs.
/// `toggle`: after the first dump, wait until cycle `t` and switch the unit off and on again.
fn program(frames: u32, lut: &[u8; 256], toggle: Option<u32>) -> Prog {
    let mut p = Prog::new();
    p.li(S0, map::VISION)
        .li(S1, map::PLIC)
        .li(A1, map::SIM_CTRL + 4);
    // class table: 64 words from the data after the code
    let table_li = p.hole(2);
    p.li(T1, 64).i(isa::addi(A2, S0, 0x100));
    let l = p.here();
    p.i(isa::lw(T0, A0, 0))
        .i(isa::sw(T0, A2, 0))
        .i(isa::addi(A0, A0, 4))
        .i(isa::addi(A2, A2, 4))
        .i(isa::addi(T1, T1, -1));
    let back = l as i32 - p.here() as i32;
    p.i(isa::bne(T1, ZERO, back));
    // PLIC: priority 1 for the unit's source, enabled; MEIE (MIE stays clear: WFI only wakes)
    p.li(T0, 1).i(isa::sw(T0, S1, 4 * irq::VISION as i32));
    p.li(T0, 1 << irq::VISION)
        .li(T1, map::PLIC + 0x2000)
        .i(isa::sw(T0, T1, 0));
    p.li(T0, 1 << 11).i(isa::csrrs(ZERO, isa::csr::MIE, T0));
    p.li(T0, ctrl::ENABLE | ctrl::IRQ_ENABLE)
        .i(isa::sw(T0, S0, field::CTRL.start as i32));
    p.li(A3, frames).li(A4, map::PLIC + 0x20_0004).li(A5, 0);
    let frame_loop = p.here();
    // first frame: poll STATUS.FRAME; later ones: WFI
    let skip_poll = p.hole(1);
    let poll = p.here();
    p.i(isa::lw(T0, S0, field::STATUS.start as i32))
        .i(isa::andi(T0, T0, status::FRAME as i32));
    let b = poll as i32 - p.here() as i32;
    p.i(isa::beq(T0, ZERO, b));
    let after_poll = p.hole(1);
    let wfi_at = p.here();
    p.i(isa::WFI);
    let joined = p.here();
    p.words[skip_poll] = isa::bne(A5, ZERO, (wfi_at - p.addr_of(skip_poll)) as i32);
    p.words[after_poll] = isa::jal(ZERO, (joined - p.addr_of(after_poll)) as i32);
    // claim, acknowledge, complete
    p.i(isa::lw(T0, A4, 0))
        .li(T1, status::FRAME)
        .i(isa::sw(T1, S0, field::STATUS.start as i32))
        .i(isa::sw(T0, A4, 0));
    console_word(&mut p, T0);
    // the header and the control words
    p.i(isa::addi(T1, S0, 0))
        .li(A2, (HEADER_LEN / 4 + 2) as u32);
    let h = p.here();
    p.i(isa::lw(T0, T1, 0));
    console_word(&mut p, T0);
    p.i(isa::addi(T1, T1, 4)).i(isa::addi(A2, A2, -1));
    let b = h as i32 - p.here() as i32;
    p.i(isa::bne(A2, ZERO, b));
    // the ready buffer: count = COUNT[ready], base = 0x4000 + ready * 0x4000
    p.i(isa::lw(T0, S0, field::READY.start as i32))
        .i(isa::slli(T1, T0, 2))
        .i(isa::add(T1, T1, S0))
        .i(isa::lw(A2, T1, field::COUNT[0].start as i32))
        .i(isa::addi(T0, T0, 1))
        .i(isa::slli(T0, T0, 14))
        .i(isa::add(T1, T0, S0));
    let skip = p.hole(1);
    let r = p.here();
    p.i(isa::lw(T0, T1, 0));
    console_word(&mut p, T0);
    p.i(isa::addi(T1, T1, 4)).i(isa::addi(A2, A2, -1));
    let b = r as i32 - p.here() as i32;
    p.i(isa::bne(A2, ZERO, b));
    let done = p.here();
    p.words[skip] = isa::beq(A2, ZERO, (done - p.addr_of(skip)) as i32);
    if let Some(t) = toggle {
        // once: wait until cycle t (inside the next frame's stream), then off and on again
        let once = p.hole(1);
        p.li(T0, t);
        let d = p.here();
        p.i(isa::csrr(T1, isa::csr::MCYCLE));
        let b = d as i32 - p.here() as i32;
        p.i(isa::bltu(T1, T0, b));
        p.i(isa::sw(ZERO, S0, field::CTRL.start as i32))
            .li(T0, ctrl::ENABLE | ctrl::IRQ_ENABLE)
            .i(isa::sw(T0, S0, field::CTRL.start as i32));
        let end = p.here();
        p.words[once] = isa::bne(A5, ZERO, (end - p.addr_of(once)) as i32);
    }
    p.li(A5, 1).i(isa::addi(A3, A3, -1));
    let b = frame_loop as i32 - p.here() as i32;
    p.i(isa::bne(A3, ZERO, b));
    p.exit_pass();
    let table = p.here();
    let li = isa::li(A0, table);
    assert!(li.len() <= 2);
    for (k, w) in li.into_iter().chain([isa::NOP]).take(2).enumerate() {
        p.words[table_li + k] = w;
    }
    for q in lut.chunks(4) {
        p.words.push(u32::from_le_bytes([
            q[0] & 15,
            q[1] & 15,
            q[2] & 15,
            q[3] & 15,
        ]));
    }
    p
}

/// Renders `n` views of the arena: a car driving towards three others.
fn rendered_frames(n: usize) -> (u16, u16, Vec<Vec<u8>>) {
    let mut cam = SyntheticCamera::new(CameraConfig::default(), 7);
    let g = cam.geometry();
    let mut frames = Vec::new();
    for k in 0..n {
        let viewer = CarPose {
            id: 0,
            x_mm: 700.0 + 20.0 * k as f32,
            y_mm: 300.0 + 60.0 * k as f32,
            yaw_rad: std::f32::consts::FRAC_PI_2 - 0.05 * k as f32,
        };
        let cars = [
            viewer,
            CarPose {
                id: 1,
                x_mm: 700.0,
                y_mm: 800.0,
                yaw_rad: 0.3,
            },
            CarPose {
                id: 2,
                x_mm: 950.0,
                y_mm: 1100.0,
                yaw_rad: 1.0,
            },
            CarPose {
                id: 6,
                x_mm: 500.0,
                y_mm: 1300.0,
                yaw_rad: 2.0,
            },
        ];
        let mut f = vec![0u8; g.frame_len()];
        cam.render(&viewer, &cars, &mut f).expect("renders");
        frames.push(f);
    }
    (g.width, g.height, frames)
}

struct Outcome {
    console: Vec<u8>,
}

/// Runs the program on the RTL and the model with `frames` streamed from cycle `start`, one a
/// period apart; demands the same records and events; returns the console bytes.
fn run_both(prog: &Prog, w: u16, h: u16, frames: &[Vec<u8>], start: u64) -> Outcome {
    let timing = CameraTiming::default();
    let max_cycles = start + PERIOD * (frames.len() as u64 + 1);
    let mut soc = Soc::new();
    soc.load_words(RAM_BASE, &prog.words).expect("fits");
    soc.release();
    let mut m = soc_model::Soc::new();
    m.load_words(RAM_BASE, &prog.words).expect("fits");
    for (k, f) in frames.iter().enumerate() {
        let at = start + PERIOD * k as u64;
        let a = soc.camera_frame_at(at, f, w, h, timing).expect("frame");
        let b = m.camera_frame_at(at, f, w, h, timing).expect("frame");
        assert_eq!(a, b);
    }
    let (records, events) = soc.run_records(max_cycles);
    assert!(
        events.iter().any(|e| e.value == Event::Exit(Exit::Pass)),
        "the program did not finish: {} records",
        records.len()
    );
    let (mut out, mut trace) = (Vec::new(), Vec::new());
    m.run_until_traced(soc.cycle(), &mut out, &mut trace);
    compare_records(&records, &trace);
    assert_eq!(
        rtl_events(&events),
        model_events(&out),
        "events: RTL vs model"
    );
    let console = out
        .iter()
        .filter_map(|s| match s.output {
            soc_model::Output::Console(b) => Some(b),
            _ => None,
        })
        .collect();
    Outcome { console }
}

/// The dumps in the console bytes: (claimed source, header and control words, run words).
fn dumps(console: &[u8]) -> Vec<(u32, Vec<u32>, Vec<u32>)> {
    let words: Vec<u32> = console
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let mut out = Vec::new();
    let mut i = 0;
    let hw = HEADER_LEN / 4 + 2;
    while i + 1 + hw <= words.len() {
        let src = words[i];
        let head = words[i + 1..i + 1 + hw].to_vec();
        let ready = head[field::READY.start / 4] as usize;
        let count = head[field::COUNT[ready].start / 4] as usize;
        let runs = words[i + 1 + hw..i + 1 + hw + count].to_vec();
        i += 1 + hw + count;
        out.push((src, head, runs));
    }
    assert_eq!(i, words.len(), "whole dumps");
    out
}

#[test]
fn rendered_frames_give_the_same_runs_on_the_rtl_the_model_and_the_encoder() {
    let (w, h, frames) = rendered_frames(4);
    let lut = *MARKER_CLASSES.table();
    // the first frame only activates the unit; the next three are dumped
    let prog = program(3, &lut, None);
    let o = run_both(&prog, w, h, &frames, 2_000);
    let d = dumps(&o.console);
    assert_eq!(d.len(), 3);
    for (k, (src, head, runs)) in d.iter().enumerate() {
        // the first wait polls, the later ones wake on the line; the claim is the unit's
        assert_eq!(*src, irq::VISION);
        assert_eq!(head[field::SEQUENCE.start / 4], k as u32 + 1);
        let mut want = vec![0u32; soc_model::VISION_CAPACITY];
        let s = encode_codes(&frames[k + 1], w, &lut, &mut want);
        want.truncate(s.words);
        assert!(
            runs == &want,
            "frame {}: the runs differ from the encoder's",
            k + 1
        );
        assert!(
            runs.len() > 20,
            "the views show markers: {} words",
            runs.len()
        );
        let ready = head[field::READY.start / 4] as usize;
        assert_eq!(
            head[field::SIZE[ready].start / 4],
            u32::from(w) | u32::from(h) << 16
        );
        assert_eq!(head[field::DROPPED[ready].start / 4], 0);
    }
}

#[test]
fn a_full_buffer_and_a_unit_switched_off_mid_frame_agree_with_the_model() {
    // noise: about one run per two pixels, more than the 4096 words a buffer holds
    let (w, h) = (160u16, 80u16);
    let mut s = 0x1234_5678u32;
    let mut noise = || {
        (0..usize::from(w) * usize::from(h))
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 17;
                s ^= s << 5;
                (s >> 7) as u8 & 3
            })
            .collect::<Vec<u8>>()
    };
    let frames: Vec<Vec<u8>> = (0..5).map(|_| noise()).collect();
    let mut lut = [0u8; 256];
    lut[1] = 1;
    lut[2] = 2;
    lut[3] = 15;
    // frame 0 activates the unit, frame 1 is dumped, frame 2 is dropped (the unit is switched
    // off and on while it streams) and its end activates the unit again, frame 3 is dumped
    let start = 500;
    let toggle = start + 2 * PERIOD + 5_000;
    let prog = program(2, &lut, Some(toggle as u32));
    let o = run_both(&prog, w, h, &frames, start);
    let d = dumps(&o.console);
    assert_eq!(d.len(), 2);
    for ((_, head, runs), (frame, seq)) in d.iter().zip([(1, 1), (3, 2)]) {
        let mut want = vec![0u32; soc_model::VISION_CAPACITY];
        let st = encode_codes(&frames[frame], w, &lut, &mut want);
        assert!(st.dropped > 0);
        want.truncate(st.words);
        assert!(
            runs == &want,
            "frame {frame}: the runs differ from the encoder's"
        );
        assert_eq!(head[field::SEQUENCE.start / 4], seq);
        let ready = head[field::READY.start / 4] as usize;
        assert_eq!(head[field::DROPPED[ready].start / 4], u32::from(st.dropped));
        assert_eq!(
            head[field::COUNT[ready].start / 4] as usize,
            soc_model::VISION_CAPACITY
        );
    }
}
