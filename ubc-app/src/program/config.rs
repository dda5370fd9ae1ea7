//! Program configuration: timeouts, bring-up back-off and the radio key.

use radio_mac::Key;

/// The testbed's default ground-station key (16 bytes, documented in `docs/ubc-app.md`):
/// the ASCII text `ALMC-testbed-key`. Replace it for any shared testbed.
pub const DEFAULT_KEY: [u8; 16] = *b"ALMC-testbed-key";

/// Everything that tunes the program. Times are in milliseconds.
#[derive(Debug, Clone)]
#[non_exhaustive]
pub struct Config {
    /// Ground-station key for authenticated console commands.
    pub key: Key,
    /// Car ID to use on the radio before READ_ID answers; `None`: the radio starts with the
    /// ID the LBC reports (or [`Config::fallback_car_id`] once the LBC stayed silent for
    /// [`Config::radio_fallback_ms`]).
    pub car_id: Option<u8>,
    /// Car ID when the LBC never reported one.
    pub fallback_car_id: u8,
    /// Wait for READ_ID this long before starting the radio with the fallback ID.
    pub radio_fallback_ms: u32,
    /// First bring-up retry delay; doubles per failure up to [`Config::bringup_backoff_max_ms`].
    pub bringup_backoff_ms: u32,
    /// Longest bring-up retry delay.
    pub bringup_backoff_max_ms: u32,
    /// No STREAM frame for this long while running: the LBC link is lost (reset or cable).
    pub stream_timeout_ms: u32,
    /// While streaming is off on purpose, READ_ID is sent this often to check the link.
    pub ping_interval_ms: u32,
    /// No authenticated command or heartbeat from the ground station for this long: stop.
    pub user_link_timeout_ms: u32,
    /// How long the red LED shows a past LBC link failure once the LBC answers again.
    pub error_led_ms: u32,
    /// A go-to point counts as reached within this distance, tracking units (2.5 mm).
    pub arrive_radius: u16,
    /// Extra stream variables (28-bit format word) on top of [`crate::program::REQUIRED_STREAM`].
    pub extra_stream: u32,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            key: Key::new(DEFAULT_KEY),
            car_id: None,
            fallback_car_id: 126,
            radio_fallback_ms: 3_000,
            bringup_backoff_ms: 100,
            bringup_backoff_max_ms: 2_000,
            stream_timeout_ms: 300,
            ping_interval_ms: 500,
            user_link_timeout_ms: 3_000,
            error_led_ms: 5_000,
            arrive_radius: 12,
            extra_stream: 0,
        }
    }
}
