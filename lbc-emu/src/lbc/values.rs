//! Conversions from the firmware's floating-point state to the protocol's range-checked
//! field types: values are clamped into range first, so no conversion can fail at run time.

use super::*;

pub(super) fn clamp_x(units: f64) -> XCoord {
    let v = units
        .round()
        .clamp(f64::from(XCoord::MIN), f64::from(XCoord::MAX)) as u16;
    XCoord::new(v).unwrap_or(X0)
}

pub(super) fn clamp_y(units: f64) -> YCoord {
    let v = units
        .round()
        .clamp(f64::from(YCoord::MIN), f64::from(YCoord::MAX)) as u16;
    YCoord::new(v).unwrap_or(Y0)
}

pub(super) fn heading(rad: f64) -> Heading {
    let mrad = (wrap_2pi(rad) * 1000.0).round().clamp(0.0, 6283.0) as u16;
    Heading::new(mrad).unwrap_or(H0)
}

pub(super) fn steering(mrad: f64) -> SteeringAngle {
    let lim = f64::from(STEER_LIMIT_MRAD);
    SteeringAngle::new(mrad.round().clamp(-lim, lim) as i16).unwrap_or(S0)
}

pub(super) fn velocity(mm_s: f64) -> Velocity {
    Velocity::new(mm_s.round().clamp(-8192.0, 8191.0) as i16).unwrap_or(V0)
}

pub(super) fn i14(v: f64) -> I14 {
    I14::new(v.round().clamp(-8192.0, 8191.0) as i16).unwrap_or(I14::from_bits(0))
}

pub(super) fn i28(v: f64) -> I28 {
    let lim = f64::from(1i32 << 27);
    I28::new(v.round().clamp(-lim, lim - 1.0) as i32).unwrap_or(I28_0)
}

pub(super) fn u14(v: u16) -> U14 {
    U14::new(v.min(0x3FFF)).unwrap_or(U14_0)
}

// Valid values of each field type, checked at compile time; used where a clamped value is
// turned into its type so that no run-time path can panic.
macro_rules! valid {
    ($name:ident: $t:ty = $e:expr) => {
        pub(super) const $name: $t = match $e {
            Ok(v) => v,
            Err(_) => panic!("constant out of range"),
        };
    };
}
valid!(X0: XCoord = XCoord::new(0));
valid!(Y0: YCoord = YCoord::new(0));
valid!(H0: Heading = Heading::new(0));
valid!(S0: SteeringAngle = SteeringAngle::new(0));
valid!(V0: Velocity = Velocity::new(0));
valid!(I28_0: I28 = I28::new(0));
valid!(U14_0: U14 = U14::new(0));
valid!(ID0: VehicleId = VehicleId::new(0));
valid!(TEMP0: ChipTemperature = ChipTemperature::new(0));
valid!(LED_OFF: LedPattern = LedPattern::from_bits(0));
valid!(GPIO_OFF: GpioPattern = GpioPattern::from_bits(0));
