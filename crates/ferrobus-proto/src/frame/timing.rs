//! Serial line settings and the timing they imply: character time, t1.5 and t3.5.
//!
//! Spec: MODBUS over Serial Line V1.02 §2.5.1 and §2.5.1.1. A character is a start bit, the
//! data bits, the parity bit if any, and the stop bits: 11 bits for RTU's 8E1, 8O1 and 8N2.
//! Frames are separated by at least 3.5 character times of silence (t3.5); a gap of more
//! than 1.5 character times inside a frame makes it incomplete (t1.5). "For baud rates
//! greater than 19200 Bps, fixed values for the 2 timers should be used: … 750 µs for the
//! inter-character time-out (t1.5) and … 1.750 ms for inter-frame delay (t3.5)."
//!
//! Every duration here is rounded **up** to the nanosecond: a timer that fires early breaks
//! the rule it enforces, one that fires a nanosecond late does not. At 9600 8E1 that makes
//! t3.5 = 3.5 × 11 / 9600 s = 4.010417 ms.
//!
//! Both timers can be overridden: USB adapters deliver bytes in bursts, some drives want
//! longer gaps (Delta-heritage servos ask for 10 ms), and other stacks use other values.

use core::fmt;
use core::time::Duration;

/// Parity of a serial character.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, Default)]
pub enum Parity {
    /// No parity bit. The spec then asks for two stop bits.
    None,
    /// Even parity: the spec's default.
    #[default]
    Even,
    /// Odd parity.
    Odd,
}

/// Data bits per character: 8 for RTU, 7 for ASCII.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, Default)]
pub enum DataBits {
    /// 7 data bits (ASCII mode).
    Seven,
    /// 8 data bits (RTU mode).
    #[default]
    Eight,
}

/// Stop bits per character.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, Default)]
pub enum StopBits {
    /// One stop bit.
    #[default]
    One,
    /// Two stop bits.
    Two,
}

/// The settings of a serial line.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct LineConfig {
    baud: u32,
    /// Data bits per character.
    pub data_bits: DataBits,
    /// Parity.
    pub parity: Parity,
    /// Stop bits.
    pub stop_bits: StopBits,
}

impl LineConfig {
    /// A line at `baud` (must not be zero) with 8 data bits, even parity and one stop bit,
    /// the spec's default format.
    pub const fn new(baud: u32) -> Option<Self> {
        if baud == 0 {
            return None;
        }
        Some(LineConfig { baud, data_bits: DataBits::Eight, parity: Parity::Even, stop_bits: StopBits::One })
    }

    /// The same line with another parity.
    #[must_use]
    pub const fn with_parity(mut self, parity: Parity) -> Self {
        self.parity = parity;
        self
    }

    /// The same line with other data bits.
    #[must_use]
    pub const fn with_data_bits(mut self, data_bits: DataBits) -> Self {
        self.data_bits = data_bits;
        self
    }

    /// The same line with other stop bits.
    #[must_use]
    pub const fn with_stop_bits(mut self, stop_bits: StopBits) -> Self {
        self.stop_bits = stop_bits;
        self
    }

    /// Bits per second.
    pub const fn baud(&self) -> u32 {
        self.baud
    }

    /// Bits per character: start + data + parity + stop.
    pub const fn bits_per_char(&self) -> u32 {
        let data = match self.data_bits {
            DataBits::Seven => 7,
            DataBits::Eight => 8,
        };
        let parity = match self.parity {
            Parity::None => 0,
            Parity::Even | Parity::Odd => 1,
        };
        let stop = match self.stop_bits {
            StopBits::One => 1,
            StopBits::Two => 2,
        };
        1u32.saturating_add(data).saturating_add(parity).saturating_add(stop)
    }
}

impl Default for LineConfig {
    /// 19200 8E1: the spec's recommended default.
    fn default() -> Self {
        LineConfig { baud: 19_200, data_bits: DataBits::Eight, parity: Parity::Even, stop_bits: StopBits::One }
    }
}

/// `9600 8E1`
impl fmt::Display for LineConfig {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let data = match self.data_bits {
            DataBits::Seven => '7',
            DataBits::Eight => '8',
        };
        let parity = match self.parity {
            Parity::None => 'N',
            Parity::Even => 'E',
            Parity::Odd => 'O',
        };
        let stop = match self.stop_bits {
            StopBits::One => '1',
            StopBits::Two => '2',
        };
        write!(f, "{} {data}{parity}{stop}", self.baud)
    }
}

/// The timers of a line: character time, t1.5 and t3.5.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct LineTiming {
    char_time: Duration,
    t1_5: Duration,
    t3_5: Duration,
}

/// Above this rate the spec fixes t1.5 and t3.5 instead of counting characters.
pub const FIXED_TIMING_ABOVE_BAUD: u32 = 19_200;
/// t1.5 above 19200 baud (§2.5.1.1).
pub const FIXED_T1_5: Duration = Duration::from_micros(750);
/// t3.5 above 19200 baud (§2.5.1.1).
pub const FIXED_T3_5: Duration = Duration::from_micros(1750);

/// How long a PC waits for the rest of an RTU frame of known length: OS serial stacks and USB
/// adapters deliver a frame in bursts separated by milliseconds, well above t3.5 at high
/// baud rates. Noise costs nothing extra: the receiver resyncs past it anyway. Not from the
/// spec: ferrobus's choice for hosts that do not see the line itself.
pub const PC_INCOMPLETE_TIMEOUT: Duration = Duration::from_millis(20);

/// The silence that ends an RTU frame of unknown length on a stream without a line (RTU over
/// TCP), where no character time exists. Not from the spec: ferrobus's choice.
pub const STREAM_FRAME_GAP: Duration = Duration::from_millis(50);

/// `numerator_bits × 10⁹ / (denominator × baud)` nanoseconds, rounded up.
fn ceil_nanos(bits_times_halves: u64, halves: u64, baud: u32) -> Duration {
    let num = bits_times_halves.saturating_mul(1_000_000_000);
    let den = halves.saturating_mul(u64::from(baud)).max(1);
    Duration::from_nanos(num.div_ceil(den))
}

impl LineTiming {
    /// The timing of `line`, with the spec's fixed t1.5/t3.5 above 19200 baud.
    pub fn new(line: &LineConfig) -> Self {
        let bits = u64::from(line.bits_per_char());
        let baud = line.baud();
        let char_time = ceil_nanos(bits, 1, baud);
        if baud > FIXED_TIMING_ABOVE_BAUD {
            return LineTiming { char_time, t1_5: FIXED_T1_5, t3_5: FIXED_T3_5 };
        }
        LineTiming {
            char_time,
            t1_5: ceil_nanos(bits.saturating_mul(3), 2, baud),
            t3_5: ceil_nanos(bits.saturating_mul(7), 2, baud),
        }
    }

    /// Timing with no silent intervals at all, for byte streams that have no line under them
    /// (a TCP socket carrying RTU frames, an unpaced pty in a benchmark): nothing waits
    /// before transmitting. Give the receiver a frame gap
    /// ([`RtuCodec::with_frame_gap`](super::rtu::RtuCodec::with_frame_gap)) to end frames
    /// whose length the function code cannot tell.
    pub const fn unpaced() -> Self {
        LineTiming { char_time: Duration::ZERO, t1_5: Duration::ZERO, t3_5: Duration::ZERO }
    }

    /// The same timing with t1.5 overridden.
    #[must_use]
    pub const fn with_t1_5(mut self, t1_5: Duration) -> Self {
        self.t1_5 = t1_5;
        self
    }

    /// The same timing with t3.5 overridden.
    #[must_use]
    pub const fn with_t3_5(mut self, t3_5: Duration) -> Self {
        self.t3_5 = t3_5;
        self
    }

    /// Time to send one character.
    pub const fn char_time(&self) -> Duration {
        self.char_time
    }

    /// The longest gap allowed between two characters of a frame.
    pub const fn t1_5(&self) -> Duration {
        self.t1_5
    }

    /// The silent interval that separates frames.
    pub const fn t3_5(&self) -> Duration {
        self.t3_5
    }

    /// Time to send `n` characters back to back.
    pub fn transmit_time(&self, n: usize) -> Duration {
        let n = u32::try_from(n).unwrap_or(u32::MAX);
        self.char_time.checked_mul(n).unwrap_or(Duration::MAX)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pc_timeouts_outlast_the_spec_gaps_at_9600_baud_and_above() {
        let at_9600 = LineTiming::new(&LineConfig::new(9600).unwrap());
        assert!(PC_INCOMPLETE_TIMEOUT > at_9600.t3_5());
        assert!(PC_INCOMPLETE_TIMEOUT > FIXED_T3_5);
        assert!(STREAM_FRAME_GAP >= PC_INCOMPLETE_TIMEOUT);
    }

    fn line(baud: u32, parity: Parity, stop: StopBits) -> LineConfig {
        LineConfig::new(baud).unwrap().with_parity(parity).with_stop_bits(stop)
    }

    #[test]
    fn t3_5_at_9600_8e1_is_4010417_ns_rounded_up() {
        let t = LineTiming::new(&line(9600, Parity::Even, StopBits::One));
        assert_eq!(t.char_time(), Duration::from_nanos(1_145_834));
        assert_eq!(t.t1_5(), Duration::from_nanos(1_718_750));
        assert_eq!(t.t3_5(), Duration::from_nanos(4_010_417));
    }

    #[test]
    fn reference_table_values_for_11_bit_characters() {
        // shared/reference/modbus-and-drives.md §1.2, rounded up to the nanosecond.
        let cases = [
            (1200, 9_166_667, 13_750_000, 32_083_334),
            (2400, 4_583_334, 6_875_000, 16_041_667),
            (4800, 2_291_667, 3_437_500, 8_020_834),
            (19_200, 572_917, 859_375, 2_005_209),
        ];
        for (baud, ch, t15, t35) in cases {
            let t = LineTiming::new(&line(baud, Parity::Even, StopBits::One));
            assert_eq!(t.char_time().as_nanos(), ch, "char at {baud}");
            assert_eq!(t.t1_5().as_nanos(), t15, "t1.5 at {baud}");
            assert_eq!(t.t3_5().as_nanos(), t35, "t3.5 at {baud}");
        }
    }

    #[test]
    fn above_19200_the_timers_are_fixed_but_the_character_time_is_not() {
        let t = LineTiming::new(&line(115_200, Parity::None, StopBits::One));
        assert_eq!(t.t1_5(), Duration::from_micros(750));
        assert_eq!(t.t3_5(), Duration::from_micros(1750));
        assert_eq!(t.char_time(), Duration::from_nanos(86_806)); // 10 bits
        let t = LineTiming::new(&line(38_400, Parity::Even, StopBits::One));
        assert_eq!(t.t3_5(), Duration::from_micros(1750));
    }

    #[test]
    fn bits_per_character_follow_the_format() {
        assert_eq!(line(9600, Parity::Even, StopBits::One).bits_per_char(), 11);
        assert_eq!(line(9600, Parity::None, StopBits::Two).bits_per_char(), 11);
        assert_eq!(line(9600, Parity::None, StopBits::One).bits_per_char(), 10);
        let ascii = line(9600, Parity::Even, StopBits::One).with_data_bits(DataBits::Seven);
        assert_eq!(ascii.bits_per_char(), 10);
    }

    #[test]
    fn overrides_replace_the_computed_timers() {
        let t = LineTiming::new(&LineConfig::default())
            .with_t1_5(Duration::from_millis(2))
            .with_t3_5(Duration::from_millis(10));
        assert_eq!(t.t1_5(), Duration::from_millis(2));
        assert_eq!(t.t3_5(), Duration::from_millis(10));
    }

    #[test]
    fn zero_baud_is_refused_and_transmit_time_saturates() {
        assert!(LineConfig::new(0).is_none());
        let t = LineTiming::new(&LineConfig::new(1).unwrap());
        assert_eq!(t.transmit_time(usize::MAX), Duration::from_secs(11).checked_mul(u32::MAX).unwrap());
        assert_eq!(LineTiming::new(&LineConfig::default()).transmit_time(8), Duration::from_nanos(572_917 * 8));
    }

    #[test]
    fn display_is_the_usual_shorthand() {
        extern crate std;
        assert_eq!(std::format!("{}", line(9600, Parity::Even, StopBits::One)), "9600 8E1");
    }
}
