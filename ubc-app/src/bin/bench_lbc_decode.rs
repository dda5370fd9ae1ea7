//! On-target benchmark of the LBC receive path: RV32 instructions per received byte to
//! deframe and decode a 30 Hz STREAM that carries every valid system variable.
//!
//! At startup the program encodes [`FRAMES`] STREAM messages of a car driving around the
//! arena into RAM with `lbc-link` (not measured). It then reads `minstret` around each
//! measured region. Under `qemu-system-riscv32 -icount shift=0` that counter is an exact
//! count of retired instructions. Every run checks this: loops of 1000 and 2000 iterations
//! of a two-instruction loop must differ by exactly 2000, or the run fails with
//! [`EXIT_NOT_EXACT`]. A count includes one instruction of the reads themselves (the
//! 1000-iteration loop reads 2001). Each region is logged as one defmt line
//! `bench stage=NAME instructions=N bytes=N frames=N`; `cargo xtask bench` reads them.
//!
//! Interrupts stay disabled (the board is not brought up), so no handler runs inside a
//! measured region.

#![no_std]
#![no_main]
#![forbid(unsafe_code)]

use ubc_hal::boards::qemu_virt as board;

use core::hint::black_box;

use lbc_link::header::STREAM;
use lbc_link::{
    decode_all, ChipStatus, ChipTemperature, Deframer, Heading, Position, RangeError,
    SteerVelocity, SteeringAngle, StreamFormat, StreamSample, Velocity, Warnings, I14, I28,
    MAX_FRAME_LEN, U14,
};

/// Messages in the recording: ten seconds of a 30 Hz stream.
const FRAMES: usize = 300;
/// Bytes of one STREAM message with every variable: header, 58 data bytes, checksum, end.
const FULL_FRAME_LEN: usize = 61;
/// Size of the recording.
const BYTES: usize = FRAMES * FULL_FRAME_LEN;
/// Iterations of the calibration loops (two instructions each).
const LOOP_SHORT: u32 = 1000;
const LOOP_LONG: u32 = 2000;

/// Exit status: a sample could not be encoded.
const EXIT_ENCODE: u16 = 5;
/// Exit status: `minstret` is not an exact instruction count (QEMU without `-icount`).
const EXIT_NOT_EXACT: u16 = 6;
/// Exit status: a stage did not decode every message.
const EXIT_DECODE: u16 = 7;
/// Exit status: panic.
const EXIT_PANIC: u16 = 1;

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

/// A small deterministic noise source for sensor readings.
struct Noise(u32);

impl Noise {
    fn next(&mut self, span: u16) -> u16 {
        // xorshift32
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 17;
        self.0 ^= self.0 << 5;
        (self.0 % u32::from(span)) as u16
    }
}

/// Triangle wave over `0..=span` with period `2 * span`.
fn triangle(t: u32, span: u32) -> u32 {
    let phase = t % (2 * span);
    if phase <= span {
        phase
    } else {
        2 * span - phase
    }
}

/// Sample `i` of a car sweeping the arena at about 0.5 m/s, with noisy raw sensors.
fn sample(i: u32, noise: &mut Noise) -> Result<StreamSample, RangeError> {
    let x = 40 + triangle(i * 7, 520) as u16;
    let y = 40 + triangle(i * 5, 720) as u16;
    let position = Position::new(x, y)?;
    let heading = Heading::new(((i * 21) % 6284) as u16)?;
    let steer_velocity = SteerVelocity {
        steering: SteeringAngle::new(triangle(i * 3, 600) as i16 - 300)?,
        velocity: Velocity::new(500 + noise.next(40) as i16 - 20)?,
    };
    let target = Position::new(x.saturating_add(4).min(600), y.saturating_add(4).min(800))?;
    let signed = |n: &mut Noise, center: i16, span: u16| {
        I14::new(center.saturating_add(n.next(span) as i16 - (span / 2) as i16))
    };
    Ok(StreamSample {
        id: Some(U14::new(7)?),
        position: Some(position),
        steer_velocity: Some(steer_velocity),
        adjusted_yaw: Some(heading),
        heading: Some(Heading::new(((i * 21 + 3) % 6284) as u16)?),
        adc_steering: Some(U14::new(2048 + noise.next(64))?),
        adc_range: Some(U14::new(900 + noise.next(200))?),
        adc_gyro_reference: Some(U14::new(8192 + noise.next(8))?),
        adc_gyro_pitch: Some(signed(noise, 0, 32)?),
        adc_gyro_roll: Some(signed(noise, 0, 32)?),
        adc_gyro_yaw: Some(signed(noise, 150, 64)?),
        chip_status: Some(ChipStatus {
            temperature: ChipTemperature::new(45 + (i / 60) as u8 % 10)?,
            warnings: Warnings {
                battery_low: false,
                over_temperature: false,
            },
        }),
        target_position: Some(target),
        target_steer_velocity: Some(steer_velocity),
        target_yaw: Some(heading),
        motor_p_error: Some(signed(noise, 0, 400)?),
        motor_d_error: Some(signed(noise, 0, 100)?),
        motor_i_error: Some(I28::new(i as i32 * 37 - 5000)?),
        user: [
            Some(U14::new(1)?),
            Some(U14::new(i as u16 & 0x3FFF)?),
            Some(U14::new(noise.next(0x3FFF))?),
            Some(U14::new(0)?),
            Some(U14::new(0x3FFF)?),
            Some(U14::new(1234)?),
        ],
    })
}

/// Fills `out` with the recording; returns the number of bytes written.
fn record(format: StreamFormat, out: &mut [u8; BYTES]) -> Option<usize> {
    let mut noise = Noise(0x2545_F491);
    let mut frame = [0u8; MAX_FRAME_LEN];
    let mut len = 0;
    for i in 0..FRAMES as u32 {
        let n = sample(i, &mut noise).ok()?.emit(format, &mut frame).ok()?;
        out.get_mut(len..len + n)?.copy_from_slice(frame.get(..n)?);
        len += n;
    }
    Some(len)
}

/// The deframer alone (header check, buffering, checksum), no STREAM decoding.
fn deframe_only(bytes: &[u8]) -> usize {
    let mut deframer = Deframer::new();
    let mut frames = 0;
    for &b in bytes {
        if let Some(Ok(msg)) = deframer.push(b) {
            if msg.header == STREAM {
                frames += 1;
            }
        }
    }
    frames
}

/// The deframer fed whole blocks (`push_slice`), no STREAM decoding.
fn deframe_slice(bytes: &[u8]) -> usize {
    let mut deframer = Deframer::new();
    let mut frames = 0;
    let mut input = bytes;
    while !input.is_empty() {
        if let Some(Ok(msg)) = deframer.push_slice(&mut input) {
            if msg.header == STREAM {
                frames += 1;
            }
        }
    }
    frames
}

/// Deframe and decode, keeping every decoded sample alive (as a consumer would).
fn decode_keep(bytes: &[u8], format: StreamFormat) -> usize {
    let mut deframer = Deframer::new();
    let mut frames = 0;
    let mut input = bytes;
    while !input.is_empty() {
        if let Some(Ok(msg)) = deframer.push_slice(&mut input) {
            if msg.header == STREAM {
                if let Ok(sample) = StreamSample::decode(format, msg.data) {
                    black_box(sample);
                    frames += 1;
                }
            }
        }
    }
    frames
}

fn report(stage: &str, instructions: u32, bytes: usize, frames: usize) {
    defmt::info!(
        "bench stage={=str} instructions={=u32} bytes={=u32} frames={=u32}",
        stage,
        instructions,
        bytes as u32,
        frames as u32
    );
}

#[riscv_rt::entry]
fn main() -> ! {
    let exit = board::exit_device();
    let format = StreamFormat::ALL;
    let mut buffer = [0u8; BYTES];
    let Some(len) = record(format, &mut buffer) else {
        defmt::error!("bench: encoding the recording failed");
        exit.fail(EXIT_ENCODE)
    };
    let bytes = black_box(&buffer[..len]);
    defmt::info!(
        "bench lbc_decode format={=u32:#010x} frames={=u32} bytes={=u32}",
        format.bits(),
        FRAMES as u32,
        len as u32
    );

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

    let (deframed, deframe_n) = measure(|| deframe_only(bytes));
    report("deframe", deframe_n, len, deframed);
    let (sliced, slice_n) = measure(|| deframe_slice(bytes));
    report("deframe_slice", slice_n, len, sliced);
    let (decoded, decode_n) = measure(|| {
        let mut deframer = Deframer::new();
        decode_all(bytes, &mut deframer, format)
    });
    report("decode_all", decode_n, len, decoded);
    let (kept, keep_n) = measure(|| decode_keep(bytes, format));
    report("decode_keep", keep_n, len, kept);

    if deframed != FRAMES || sliced != FRAMES || decoded != FRAMES || kept != FRAMES {
        defmt::error!(
            "bench: decoded {=u32}/{=u32}/{=u32}/{=u32} of {=u32} messages",
            deframed as u32,
            sliced as u32,
            decoded as u32,
            kept as u32,
            FRAMES as u32
        );
        exit.fail(EXIT_DECODE)
    }
    exit.pass()
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    defmt::error!("panic: {}", defmt::Display2Format(info));
    board::exit_device().fail(EXIT_PANIC)
}
