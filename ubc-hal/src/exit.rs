//! SiFive test device ("sifive_test" on qemu virt): a register whose writes end the simulation
//! with a pass, a failure code (QEMU's exit status) or a reset.

use crate::mmio::RegisterBus;

/// Value written for a pass (QEMU exits with status 0).
pub const FINISHER_PASS: u32 = 0x5555;
/// Low half of a failure value; the exit code goes in the high half.
pub const FINISHER_FAIL: u32 = 0x3333;
/// Value written to reset the machine.
pub const FINISHER_RESET: u32 = 0x7777;

/// What to tell the test device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ExitRequest {
    /// End with status 0.
    Pass,
    /// End with this status.
    Fail(u16),
    /// Reset the machine.
    Reset,
}

impl ExitRequest {
    /// The register value that requests this.
    pub const fn encode(self) -> u32 {
        match self {
            Self::Pass => FINISHER_PASS,
            Self::Fail(code) => ((code as u32) << 16) | FINISHER_FAIL,
            Self::Reset => FINISHER_RESET,
        }
    }
}

/// The test device.
#[derive(Debug)]
pub struct TestDevice<B> {
    bus: B,
}

impl<B: RegisterBus> TestDevice<B> {
    /// Wraps the device's register.
    pub const fn new(bus: B) -> Self {
        Self { bus }
    }

    /// Sends `request`; on a machine without the device this returns.
    pub fn request(&self, request: ExitRequest) {
        self.bus.write32(0, request.encode());
    }

    /// Ends the run with status 0.
    pub fn pass(&self) -> ! {
        self.request(ExitRequest::Pass);
        halt()
    }

    /// Ends the run with status `code` (0 is reported as 1: a failure must not look like a pass).
    pub fn fail(&self, code: u16) -> ! {
        self.request(ExitRequest::Fail(code.max(1)));
        halt()
    }

    /// Resets the machine.
    pub fn reset(&self) -> ! {
        self.request(ExitRequest::Reset);
        halt()
    }
}

fn halt() -> ! {
    loop {
        core::hint::spin_loop();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mmio::testing::RamBus;

    #[test]
    fn encodings() {
        assert_eq!(ExitRequest::Pass.encode(), 0x5555);
        assert_eq!(ExitRequest::Fail(1).encode(), 0x0001_3333);
        assert_eq!(ExitRequest::Fail(0xABCD).encode(), 0xABCD_3333);
        assert_eq!(ExitRequest::Reset.encode(), 0x7777);
    }

    #[test]
    fn request_writes_the_register() {
        let bus = RamBus::new(4);
        TestDevice::new(&bus).request(ExitRequest::Fail(3));
        assert_eq!(bus.read32(0), 0x0003_3333);
    }
}
