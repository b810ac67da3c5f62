//! Identify: blink the board LED (PC13, active low) so a user can tell which luminaire answers
//! (`Identify` request). 5 Hz for the requested seconds; a new request restarts or (0)
//! ends the blink.

use embassy_futures::select::{Either, select};
use embassy_stm32::gpio::Output;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::signal::Signal;
use embassy_time::{Duration, Instant, Timer};

/// Half period of the blink.
const HALF_PERIOD: Duration = Duration::from_millis(100);

/// Identify requests: blink for this many seconds (0 = stop).
pub static IDENTIFY: Signal<CriticalSectionRawMutex, u8> = Signal::new();

/// The board LED, active low.
pub struct BoardLed<'d>(Output<'d>);

impl<'d> BoardLed<'d> {
    /// Wraps the PC13 output (created high = off).
    pub fn new(pin: Output<'d>) -> Self {
        Self(pin)
    }

    /// Switches the LED on or off.
    pub fn set(&mut self, on: bool) {
        if on {
            self.0.set_low();
        } else {
            self.0.set_high();
        }
    }
}

/// Blinks `led` for `seconds`; returns early with the next request if one arrives.
pub async fn blink(led: &mut BoardLed<'_>, seconds: u8) -> Option<u8> {
    let end = Instant::now() + Duration::from_secs(u64::from(seconds));
    let mut on = true;
    while Instant::now() < end {
        led.set(on);
        on = !on;
        if let Either::Second(next) = select(Timer::after(HALF_PERIOD), IDENTIFY.wait()).await {
            led.set(false);
            return Some(next);
        }
    }
    led.set(false);
    None
}
