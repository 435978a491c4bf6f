//! A UART receiver on a line whose transmitter uses other settings: what a real serial port
//! set to the wrong baud rate, parity or data bits makes of the characters on the wire.
//!
//! Sans-IO and exact: the characters sent back to back at the transmitter's settings become a
//! bit stream (start bit 0, data bits least significant first, the parity bit, stop bits 1,
//! the idle line 1), and a receiver at its own settings samples it as a UART does. In idle it
//! waits for a falling edge; it samples the start bit in its middle (a high sample there is a
//! false start: back to waiting), then every data bit, the parity bit and the first stop bit
//! in theirs, one bit time of its own apart. A parity bit that disagrees is a parity error; a
//! low first stop bit is a framing error (the data is kept, as a UART keeps it). A receiver
//! expecting two stop bits checks only the first, as UARTs do — so stop bits alone never
//! garble anything. Times are integers in units of 1 / (2 · tx baud · rx baud) s: a transmitted
//! bit lasts 2 · rx baud units, a received one 2 · tx baud, with no rounding anywhere.

use ferrobus_proto::frame::{DataBits, LineConfig, Parity, StopBits};

/// One character as the receiver decoded it.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) struct Received {
    /// The data bits (7 or 8 of them).
    pub(crate) byte: u8,
    /// The parity bit disagreed with the data.
    pub(crate) parity_error: bool,
    /// The first stop bit was low.
    pub(crate) framing_error: bool,
}

impl Received {
    /// Whether the character came without an error.
    pub(crate) fn is_clean(self) -> bool {
        !self.parity_error && !self.framing_error
    }
}

fn data_bits(config: LineConfig) -> u32 {
    match config.data_bits {
        DataBits::Seven => 7,
        DataBits::Eight => 8,
    }
}

/// Whether two settings put the same bits at the same times (stop bits aside).
pub(crate) fn compatible(tx: LineConfig, rx: LineConfig) -> bool {
    tx.baud() == rx.baud() && tx.data_bits == rx.data_bits && tx.parity == rx.parity
}

/// The parity bit that goes with `byte`'s low `bits` bits.
fn parity_bit(byte: u8, bits: u32, parity: Parity) -> Option<bool> {
    let mask = u8::try_from((1u16 << bits).saturating_sub(1)).unwrap_or(u8::MAX);
    let odd_ones = (byte & mask).count_ones() % 2 == 1;
    match parity {
        Parity::None => None,
        Parity::Even => Some(odd_ones),
        Parity::Odd => Some(!odd_ones),
    }
}

/// The bits of `bytes` sent back to back at `tx`.
fn bit_stream(tx: LineConfig, bytes: &[u8]) -> Vec<bool> {
    let bits = data_bits(tx);
    let stops = match tx.stop_bits {
        StopBits::One => 1,
        StopBits::Two => 2,
    };
    let mut stream = Vec::with_capacity(bytes.len().saturating_mul(12));
    for &byte in bytes {
        stream.push(false);
        stream.extend((0..bits).map(|i| byte >> i & 1 == 1));
        stream.extend(parity_bit(byte, bits, tx.parity));
        stream.extend(std::iter::repeat_n(true, stops));
    }
    stream
}

/// What a receiver at `rx` decodes from `bytes` sent back to back at `tx`, after and before
/// an idle line.
pub(crate) fn receive(tx: LineConfig, rx: LineConfig, bytes: &[u8]) -> Vec<Received> {
    if compatible(tx, rx) {
        let clean = |&byte: &u8| Received {
            byte: if rx.data_bits == DataBits::Seven { byte & 0x7F } else { byte },
            parity_error: false,
            framing_error: false,
        };
        return bytes.iter().map(clean).collect();
    }
    let stream = bit_stream(tx, bytes);
    let (tx_baud, rx_baud) = (u64::from(tx.baud()), u64::from(rx.baud()));
    // A transmitted bit lasts `tx_bit` units, half a received bit `rx_half`.
    let tx_bit = rx_baud.saturating_mul(2);
    let rx_half = tx_baud;
    let level = |t: u64| -> bool {
        let k = usize::try_from(t / tx_bit.max(1)).unwrap_or(usize::MAX);
        stream.get(k).copied().unwrap_or(true)
    };
    let end = u64::try_from(stream.len()).unwrap_or(u64::MAX).saturating_mul(tx_bit);
    let bits = data_bits(rx);
    let mut out = Vec::new();
    let mut t = 0u64;
    // Whether the line was high at the last instant looked at: a start needs a falling edge.
    let mut was_high = true;
    while t < end {
        // Hunt for the next falling edge: a low transmitted bit after a high one.
        let mut edge = None;
        let mut high = was_high;
        let first = usize::try_from(t / tx_bit.max(1)).unwrap_or(usize::MAX);
        for (k, &bit) in stream.iter().enumerate().skip(first) {
            if !bit && high {
                let start = u64::try_from(k).unwrap_or(u64::MAX).saturating_mul(tx_bit);
                edge = Some(start.max(t));
                break;
            }
            high = bit;
        }
        let Some(t0) = edge else { break };
        let sample = |j: u64| level(t0.saturating_add(rx_half.saturating_mul(j.saturating_mul(2).saturating_add(1))));
        if sample(0) {
            // A false start: the line was low for less than half a bit.
            t = t0.saturating_add(rx_half);
            was_high = true;
            continue;
        }
        let mut byte = 0u8;
        for i in 0..bits {
            if sample(u64::from(i) + 1) {
                byte |= 1 << i;
            }
        }
        let mut j = u64::from(bits) + 1;
        let parity_error = match parity_bit(byte, bits, rx.parity) {
            Some(expected) => {
                let got = sample(j);
                j += 1;
                got != expected
            }
            None => false,
        };
        let stop = sample(j);
        out.push(Received { byte, parity_error, framing_error: !stop });
        t = t0.saturating_add(rx_half.saturating_mul(j.saturating_mul(2).saturating_add(1)));
        was_high = stop;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(baud: u32, parity: Parity) -> LineConfig {
        LineConfig::new(baud).unwrap().with_parity(parity)
    }

    fn clean(bytes: &[u8]) -> Vec<Received> {
        bytes.iter().map(|&byte| Received { byte, parity_error: false, framing_error: false }).collect()
    }

    /// A read request, 01 03 00 00 00 01 84 0A.
    const REQUEST: &[u8] = &[0x01, 0x03, 0x00, 0x00, 0x00, 0x01, 0x84, 0x0A];

    #[test]
    fn the_same_settings_receive_every_byte_clean() {
        let l = line(9600, Parity::Even);
        assert_eq!(receive(l, l, REQUEST), clean(REQUEST));
        let all: Vec<u8> = (0..=255).collect();
        assert_eq!(receive(l, l, &all), clean(&all));
    }

    #[test]
    fn the_bit_level_model_agrees_with_the_shortcut_when_the_settings_match() {
        // Same bits, other stop bits: the shortcut does not apply, the sampling must agree.
        let tx = line(19_200, Parity::Odd).with_stop_bits(StopBits::Two);
        let rx = line(19_200, Parity::Odd);
        let all: Vec<u8> = (0..=255).collect();
        assert_eq!(receive(tx, rx, &all), clean(&all), "two stop bits sent, one expected");
        assert_eq!(receive(rx, tx, &all), clean(&all), "one sent, two expected: only the first is checked");
    }

    #[test]
    fn a_receiver_at_the_wrong_baud_rate_gets_garbage_with_errors() {
        let tx = line(9600, Parity::Even);
        for rx_baud in [4800, 19_200, 38_400, 115_200] {
            let got = receive(tx, line(rx_baud, Parity::Even), REQUEST);
            let bytes: Vec<u8> = got.iter().map(|r| r.byte).collect();
            assert_ne!(bytes, REQUEST, "at {rx_baud}");
            assert!(got.iter().any(|r| !r.is_clean()), "at {rx_baud} some character has an error: {got:?}");
        }
    }

    #[test]
    fn twice_the_baud_rate_sees_each_start_bit_and_the_low_data_bits_doubled() {
        // 0xFF at 9600 8N1: start bit, then all ones. At 19200 the receiver sees half-bits: its
        // start bit is the first half of ours, its data bit 0 the second half (low) and then
        // ones: 0xFE, and a clean stop.
        let got = receive(line(9600, Parity::None), line(19_200, Parity::None), &[0xFF]);
        assert_eq!(got, [Received { byte: 0xFE, parity_error: false, framing_error: false }]);
    }

    #[test]
    fn half_the_baud_rate_reads_two_characters_as_one_of_garbage() {
        // 00 00 at 19200 8N1: low for 9 bits, the stop bit, low for 9, the stop bit. A 9600
        // receiver samples every other bit: start, then bits 3 5 7 9 11 13 15 17 — the first
        // stop bit is its data bit 3 — and its stop bit is the second stop bit.
        let got = receive(line(19_200, Parity::None), line(9600, Parity::None), &[0x00, 0x00]);
        assert_eq!(got, [Received { byte: 0x08, parity_error: false, framing_error: false }]);
        // Exactly half: ten of its bits span two of ours, and its stop bit is always our
        // second stop bit: 256 bytes read as 128, all without an error — the worst case.
        let all: Vec<u8> = (0..=255).collect();
        let got = receive(line(19_200, Parity::None), line(9600, Parity::None), &all);
        assert_eq!(got.len(), 128);
        // 19200 into 14400 is not a whole ratio: stop samples land on data bits.
        let got = receive(line(19_200, Parity::None), line(14_400, Parity::None), &all);
        assert!(got.iter().any(|r| r.framing_error), "{got:?}");
    }

    #[test]
    fn a_parity_mismatch_is_a_parity_error_on_every_other_byte() {
        // Even sent, odd expected: every byte's parity bit is wrong.
        let got = receive(line(9600, Parity::Even), line(9600, Parity::Odd), REQUEST);
        assert_eq!(got.len(), REQUEST.len());
        assert!(got.iter().all(|r| r.parity_error && !r.framing_error), "{got:?}");
        assert_eq!(got.iter().map(|r| r.byte).collect::<Vec<_>>(), REQUEST, "the data is kept");
    }

    #[test]
    fn parity_sent_to_a_receiver_without_parity_is_a_framing_error_when_the_parity_bit_is_0() {
        // 8E1 into 8N1: the parity bit is taken for the stop bit.
        let got = receive(line(9600, Parity::Even), line(9600, Parity::None), &[0x01, 0x03]);
        // 0x01 has one 1: even parity bit 1 (a good stop); 0x03 has two: parity bit 0.
        assert_eq!(got[0], Received { byte: 0x01, parity_error: false, framing_error: false });
        assert_eq!(got[1], Received { byte: 0x03, parity_error: false, framing_error: true });
    }
}
