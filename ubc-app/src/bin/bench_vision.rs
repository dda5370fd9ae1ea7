//! On-target benchmark of the vision pipeline: RV32 instructions per pixel to find the colour
//! blobs of a 640x480 RGB332 frame, read in place from the frame-grabber window.
//!
//! The host renders a view of the arena (`arena::camera`) and publishes it into the window
//! through QEMU's shared RAM file before the firmware starts, exactly as the arena feeds a
//! running car. The program takes the frame through the board's frame grabber and reads
//! `minstret` around each measured region; under `qemu-system-riscv32 -icount shift=0` that is
//! an exact count of retired instructions (checked with two calibration loops, as in
//! `bench_lbc_decode`). Each region is logged as `bench stage=NAME instructions=N bytes=PIXELS
//! frames=BLOBS`, and every blob found as `bench blob ...`, which the host compares with its own
//! run of the same pipeline.
//!
//! Interrupts stay disabled (the board is not brought up), so no handler runs inside a
//! measured region.

#![no_std]
#![no_main]
#![forbid(unsafe_code)]

use ubc_hal::boards::qemu_virt as board;

use core::hint::black_box;

use ubc_hal::framegrabber::GrabError;
use vision::blobs::{BlobDetector, Detections, Run, MAX_RUNS_PER_ROW};
use vision::colour::MARKER_CLASSES;
use vision::frame::HeaderError;
use vision::pinhole::{CameraModel, MarkerModel};
use vision::{process_frame, row_runs_rgb332_words, FrameGeometry, PipelineConfig};

/// Iterations of the calibration loops (two instructions each).
const LOOP_SHORT: u32 = 1000;
const LOOP_LONG: u32 = 2000;

/// Exit status: panic.
const EXIT_PANIC: u16 = 1;
/// Exit status: no usable frame in the window.
const EXIT_NO_FRAME: u16 = 5;
/// Exit status: `minstret` is not an exact instruction count (QEMU without `-icount`).
const EXIT_NOT_EXACT: u16 = 6;
/// Exit status: the pipeline rejected the frame.
const EXIT_PIPELINE: u16 = 7;

/// Retired instructions since reset (low 32 bits; every region here is far shorter).
fn instret() -> u32 {
    riscv::register::minstret::read() as u32
}

/// Runs `f` between two reads of `minstret`; returns its result and the difference.
#[inline(always)]
fn measure<R>(f: impl FnOnce() -> R) -> (R, u32) {
    let start = instret();
    let result = black_box(f());
    let end = instret();
    (result, end.wrapping_sub(start))
}

fn report(stage: &str, instructions: u32, pixels: u32, blobs: u32) {
    defmt::info!(
        "bench stage={=str} instructions={=u32} bytes={=u32} frames={=u32}",
        stage,
        instructions,
        pixels,
        blobs
    );
}

/// The row scan alone (classification into runs), every row.
fn runs_only(pixels: &[u8], g: &FrameGeometry) -> u32 {
    let mut runs = [Run::default(); MAX_RUNS_PER_ROW];
    let row_words = usize::from(g.width).div_ceil(4);
    let mut total = 0u32;
    for y in 0..usize::from(g.height) {
        let start = y * g.stride;
        let Some(row) = pixels.get(start..start + 4 * row_words) else {
            break;
        };
        // The window's buffers are 4 KiB aligned and the stride a multiple of 4.
        let Some(words) = vision::as_words(row) else {
            break;
        };
        let (n, _) = row_runs_rgb332_words(words, g.width, &MARKER_CLASSES, &mut runs);
        total += n as u32;
    }
    total
}

#[riscv_rt::entry]
fn main() -> ! {
    let exit = board::exit_device();
    let mut camera = board::camera();

    // Calibration: the counter must count instructions exactly.
    let ((), empty) = measure(|| ());
    let ((), short) = measure(|| riscv::asm::delay(2 * (LOOP_SHORT - 1)));
    let ((), long) = measure(|| riscv::asm::delay(2 * (LOOP_LONG - 1)));
    report("empty", empty, 0, 0);
    report("loop1000", short, 0, 0);
    report("loop2000", long, 0, 0);
    if long.wrapping_sub(short) != 2 * (LOOP_LONG - LOOP_SHORT) {
        defmt::error!(
            "bench: minstret is not an exact instruction count (run QEMU with -icount shift=0)"
        );
        exit.fail(EXIT_NOT_EXACT)
    }

    let mut detector = BlobDetector::new();
    let config = PipelineConfig::default();
    let mut whole = 0u32;
    let grabbed = camera.with_latest(|frame| {
        let g = frame.geometry;
        let pixels = u32::from(g.width) * u32::from(g.height);
        defmt::info!(
            "bench vision frame={=u32} width={=u16} height={=u16} format={=u16}",
            frame.ticket.sequence,
            g.width,
            g.height,
            g.format.code()
        );
        let (runs, runs_n) = measure(|| runs_only(frame.pixels, &g));
        report("runs", runs_n, pixels, runs);
        let (det, n) =
            measure(|| process_frame(frame.pixels, &g, &MARKER_CLASSES, &config, &mut detector));
        let blobs = det.as_ref().map_or(0, |d| d.blobs().len() as u32);
        report("process_frame", n, pixels, blobs);
        let half = PipelineConfig {
            row_step: 2,
            ..config
        };
        let (d2, n2) =
            measure(|| process_frame(frame.pixels, &g, &MARKER_CLASSES, &half, &mut detector));
        report(
            "process_frame_rows2",
            n2,
            pixels,
            d2.map_or(0, |d| d.blobs().len() as u32),
        );
        whole = pixels;
        det
    });
    let detections: Detections = match grabbed {
        Ok(Some((_, Ok(d)))) => d,
        Ok(Some((_, Err(e)))) => {
            defmt::error!("bench: pipeline error {}", e);
            exit.fail(EXIT_PIPELINE)
        }
        Ok(None) | Err(GrabError::Header(HeaderError::NoFrame)) => {
            defmt::error!("bench: no frame published in the window");
            exit.fail(EXIT_NO_FRAME)
        }
        Err(e) => {
            defmt::error!("bench: frame grabber: {}", e);
            exit.fail(EXIT_NO_FRAME)
        }
    };
    let model = CameraModel::default();
    let marker = MarkerModel::default();
    for b in detections.blobs() {
        let (o, n) = measure(|| model.observe(b, &marker));
        report("observe", n, 0, 1);
        defmt::info!(
            "bench blob class={=u8} area={=u32} sum_x={=u32} sum_y={=u32} box={=u16},{=u16},{=u16},{=u16} bearing_mrad={=i32} range_mm={=u32}",
            b.class,
            b.area,
            b.sum_x,
            b.sum_y,
            b.min_x,
            b.min_y,
            b.max_x,
            b.max_y,
            o.bearing_mrad,
            o.range_mm
        );
    }
    defmt::info!(
        "bench vision done pixels={=u32} blobs={=u32}",
        whole,
        detections.blobs().len() as u32
    );
    exit.pass()
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    defmt::error!("panic: {}", defmt::Display2Format(info));
    board::exit_device().fail(EXIT_PANIC)
}
