//! Host benchmark: deframe and decode STREAM messages carrying every valid variable.
//!
//! The LBC streams at 30 Hz; one message with the full format is 61 bytes. The
//! benchmark decodes a recording of many such messages (with varying values) and
//! prints one markdown table row.

use std::hint::black_box;
use std::time::Instant;

use lbc_link::{
    decode_all, ChipStatus, ChipTemperature, Deframer, Heading, Position, SteerVelocity,
    SteeringAngle, StreamFormat, StreamSample, Velocity, Warnings, I14, I28, MAX_FRAME_LEN, U14,
};

const SECONDS: usize = 60;
const RATE_HZ: usize = 30;
const ROUNDS: usize = 200;

fn sample(i: usize) -> StreamSample {
    let u = |v: usize| U14::new((v % 16384) as u16).unwrap();
    let s = |v: usize| I14::new(((v % 16384) as i32 - 8192) as i16).unwrap();
    let pos = Position::new((i % 641) as u16, ((i * 3) % 961) as u16).unwrap();
    let sv = SteerVelocity {
        steering: SteeringAngle::new(((i % 1047) as i32 - 523) as i16).unwrap(),
        velocity: Velocity::new(((i * 7) % 2000) as i16 - 1000).unwrap(),
    };
    StreamSample {
        id: Some(u(7)),
        position: Some(pos),
        steer_velocity: Some(sv),
        adjusted_yaw: Some(Heading::new((i * 11 % 6284) as u16).unwrap()),
        heading: Some(Heading::new((i * 13 % 6284) as u16).unwrap()),
        adc_steering: Some(u(i * 5)),
        adc_range: Some(u(i * 17)),
        adc_gyro_reference: Some(u(512)),
        adc_gyro_pitch: Some(s(i * 19)),
        adc_gyro_roll: Some(s(i * 23)),
        adc_gyro_yaw: Some(s(i * 29)),
        chip_status: Some(ChipStatus {
            temperature: ChipTemperature::new((i % 128) as u8).unwrap(),
            warnings: Warnings {
                battery_low: i.is_multiple_of(2),
                over_temperature: i.is_multiple_of(3),
            },
        }),
        target_position: Some(pos),
        target_steer_velocity: Some(sv),
        target_yaw: Some(Heading::new(1000).unwrap()),
        motor_p_error: Some(s(i * 31)),
        motor_d_error: Some(s(i * 37)),
        motor_i_error: Some(I28::new(i as i32 * 1001 - 50_000).unwrap()),
        user: [
            Some(u(1)),
            Some(u(2)),
            Some(u(3)),
            Some(u(4)),
            Some(u(5)),
            Some(u(i)),
        ],
    }
}

fn main() {
    let format = StreamFormat::ALL;
    let frames = SECONDS * RATE_HZ;
    let mut bytes = Vec::with_capacity(frames * MAX_FRAME_LEN);
    let mut buf = [0u8; MAX_FRAME_LEN];
    for i in 0..frames {
        let n = sample(i)
            .emit(format, &mut buf)
            .expect("sample fits the format");
        bytes.extend_from_slice(&buf[..n]);
    }

    let mut deframer = Deframer::new();
    assert_eq!(decode_all(&bytes, &mut deframer, format), frames);

    let start = Instant::now();
    let mut decoded = 0;
    for _ in 0..ROUNDS {
        decoded += decode_all(black_box(&bytes), &mut deframer, black_box(format));
    }
    let elapsed = start.elapsed();
    assert_eq!(decoded, frames * ROUNDS);

    let total = (bytes.len() * ROUNDS) as f64;
    let secs = elapsed.as_secs_f64();
    println!("| benchmark | frame bytes | bytes | ns/byte | bytes/s | frames/s | 30 Hz load |");
    println!("|---|---|---|---|---|---|---|");
    println!(
        "| lbc-link decode_all, STREAM with all {} variables | {} | {} | {:.2} | {:.3e} | {:.3e} | {:.5}% |",
        format.variables().count(),
        bytes.len() / frames,
        total,
        secs * 1e9 / total,
        total / secs,
        decoded as f64 / secs,
        100.0 * RATE_HZ as f64 * secs / decoded as f64,
    );
}
