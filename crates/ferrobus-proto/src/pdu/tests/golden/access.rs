//! Goldens of the data-access codes: 0x01–0x06, 0x0F, 0x10, 0x16, 0x17 (spec §6.1–6.6,
//! §6.11, §6.12, §6.16, §6.17).

use super::*;

goldens! {
    // ── 0x01 Read Coils ──────────────────────────────────────────────────────────────────────

    /// 3G3RX p.4-168, slave 8: read coils 7–12 (`08 01 00 06 00 06 5C 90`).
    read_coils_request: Request [
        0x01,       // function code: 0x01 Read Coils
        0x00, 0x06, // starting address: 0x0006 (coil 7; the manual counts from 1)
        0x00, 0x06, // quantity of coils: 6
    ] => Request::ReadCoils(ReadBits::new(6, 6).unwrap()),
    |r| {
        let q = body!(r, Request::ReadCoils);
        assert_eq!((q.start(), q.quantity(), q.response_byte_count()), (6, 6, 1));
    }

    /// 3G3RX p.4-168: coils 7–12 are ON, ON, ON, OFF, ON, OFF (`08 01 01 17 12 1A`).
    read_coils_response: Response [
        0x01, // function code: 0x01 Read Coils
        0x01, // byte count: 1
        0x17, // 0b0001_0111: coil 7 in bit 0 … coil 12 in bit 5; bits 6 and 7 are padding
    ] => Response::ReadCoils(
        BitValues::new(Bits::from_values(&[true, true, true, false, true, false, false, false])).unwrap(),
    ),
    |r| {
        let bits = body!(r, Response::ReadCoils).values();
        assert_eq!(bits.len(), 8, "a response carries whole bytes");
        assert_eq!(bits.truncated(6), Some(Bits::from_values(&[true, true, true, false, true, false])));
    }

    // ── 0x02 Read Discrete Inputs ────────────────────────────────────────────────────────────

    /// The spec's example (§6.2): read inputs 197–218 (`11 02 00 C4 00 16`).
    read_discrete_inputs_request: Request [
        0x02,       // function code: 0x02 Read Discrete Inputs
        0x00, 0xC4, // starting address: 196 (input 197)
        0x00, 0x16, // quantity of inputs: 22
    ] => Request::ReadDiscreteInputs(ReadBits::new(196, 22).unwrap()),
    |r| {
        let q = body!(r, Request::ReadDiscreteInputs);
        assert_eq!((q.start(), q.quantity(), q.response_byte_count()), (196, 22, 3));
    }

    /// The spec's example (§6.2): inputs 197–218.
    read_discrete_inputs_response: Response [
        0x02, // function code: 0x02 Read Discrete Inputs
        0x03, // byte count: 3
        0xAC, // inputs 204…197: 1010_1100
        0xDB, // inputs 212…205: 1101_1011
        0x35, // inputs 218…213: 11_0101, two padding bits
    ] => Response::ReadDiscreteInputs(BitValues::new(Bits::from_wire(&[0xAC, 0xDB, 0x35], 24).unwrap()).unwrap()),
    |r| {
        let bits = body!(r, Response::ReadDiscreteInputs).values();
        assert_eq!(bits.len(), 24);
        // input 197 (bit 0 of 0xAC), 199 (bit 2), 218 (bit 5 of 0x35), padding (bit 6)
        let probes = [bits.get(0), bits.get(2), bits.get(21), bits.get(22)];
        assert_eq!(probes, [Some(false), Some(true), Some(true), Some(false)]);
        assert_eq!(bits.iter().take(22).filter(|&on| on).count(), 4 + 6 + 4);
    }

    // ── 0x03 Read Holding Registers ──────────────────────────────────────────────────────────

    /// Omron 3G3JX p.4-85, slave 1: read 6 registers from 0x0011 (`01 03 00 11 00 06 95 CD`).
    read_holding_registers_request: Request [
        0x03,       // function code: 0x03 Read Holding Registers
        0x00, 0x11, // starting address: 0x0011
        0x00, 0x06, // quantity of registers: 6
    ] => Request::ReadHoldingRegisters(ReadRegisters::new(0x0011, 6).unwrap()),
    |r| {
        let q = body!(r, Request::ReadHoldingRegisters);
        assert_eq!((q.start(), q.quantity()), (0x0011, 6));
    }

    /// Omron 3G3JX p.4-85: the answer (`01 03 0C 00 03 … 01 1C AF 6D`).
    read_holding_registers_response: Response [
        0x03,       // function code: 0x03 Read Holding Registers
        0x0C,       // byte count: 12 (6 registers)
        0x00, 0x03, // 0x0011: 3
        0x00, 0x00, // 0x0012: 0
        0x00, 0x63, // 0x0013: 99
        0x00, 0x00, // 0x0014: 0
        0x00, 0x1E, // 0x0015: 30
        0x01, 0x1C, // 0x0016: 284
    ] => Response::ReadHoldingRegisters(RegisterValues::new(Registers::from_values(&[3, 0, 99, 0, 30, 284])).unwrap()),
    |r| {
        let regs = body!(r, Response::ReadHoldingRegisters).values();
        assert_eq!((regs.len(), regs.byte_len()), (6, 12));
        assert!(regs.iter().eq([3, 0, 99, 0, 30, 284]));
    }

    // ── 0x04 Read Input Registers ────────────────────────────────────────────────────────────

    /// The spec's example (§6.4): read input register 9 (`11 04 00 08 00 01`).
    read_input_registers_request: Request [
        0x04,       // function code: 0x04 Read Input Registers
        0x00, 0x08, // starting address: 8 (register 30009)
        0x00, 0x01, // quantity of registers: 1
    ] => Request::ReadInputRegisters(ReadRegisters::new(8, 1).unwrap()),
    |r| {
        let q = body!(r, Request::ReadInputRegisters);
        assert_eq!((q.start(), q.quantity()), (8, 1));
    }

    /// The spec's example (§6.4): register 30009 holds 10.
    read_input_registers_response: Response [
        0x04,       // function code: 0x04 Read Input Registers
        0x02,       // byte count: 2
        0x00, 0x0A, // register 30009: 10
    ] => Response::ReadInputRegisters(RegisterValues::new(Registers::from_values(&[10])).unwrap()),
    |r| {
        let regs = body!(r, Response::ReadInputRegisters).values();
        assert_eq!((regs.len(), regs.get(0), regs.get(1)), (1, Some(10), None));
    }

    // ── 0x05 Write Single Coil ───────────────────────────────────────────────────────────────

    /// 3G3RX p.4-170, slave 10: run command ON (`0A 05 00 00 FF 00 8D 41`).
    write_single_coil_request: Request [
        0x05,       // function code: 0x05 Write Single Coil
        0x00, 0x00, // coil address: 0 (coil 1, the run command)
        0xFF, 0x00, // value: 0xFF00, ON
    ] => Request::WriteSingleCoil(WriteCoil { address: 0, value: true }),
    |r| {
        let c = body!(r, Request::WriteSingleCoil);
        assert_eq!((c.address, c.value), (0, true));
    }

    /// The echo of a coil switched OFF.
    write_single_coil_response: Response [
        0x05,       // function code: 0x05 Write Single Coil
        0x00, 0xAC, // coil address: 172 (the spec's coil 173)
        0x00, 0x00, // value: 0x0000, OFF
    ] => Response::WriteSingleCoil(WriteCoil { address: 172, value: false }),
    |r| {
        let c = body!(r, Response::WriteSingleCoil);
        assert_eq!((c.address, c.value), (172, false));
    }

    // ── 0x06 Write Single Register ───────────────────────────────────────────────────────────

    /// 3G3RX p.4-171, slave 5: A003 (register 1203h) = 50 (`05 06 12 02 00 32 AD 23`).
    write_single_register_request: Request [
        0x06,       // function code: 0x06 Write Single Register
        0x12, 0x02, // register address: 0x1202 (1203h in the manual's numbering)
        0x00, 0x32, // value: 50
    ] => Request::WriteSingleRegister(WriteRegister { address: 0x1202, value: 50 }),
    |r| {
        let w = body!(r, Request::WriteSingleRegister);
        assert_eq!((w.address, w.value), (0x1202, 50));
    }

    /// The echo of the request above.
    write_single_register_response: Response [
        0x06,       // function code: 0x06 Write Single Register
        0x12, 0x02, // register address: 0x1202
        0x00, 0x32, // value: 50
    ] => Response::WriteSingleRegister(WriteRegister { address: 0x1202, value: 50 }),
    |r| {
        let w = body!(r, Response::WriteSingleRegister);
        assert_eq!((w.address, w.value), (0x1202, 50));
    }

    // ── 0x0F Write Multiple Coils ────────────────────────────────────────────────────────────

    /// The spec's example (§6.11): coils 20–29.
    write_multiple_coils_request: Request [
        0x0F,       // function code: 0x0F Write Multiple Coils
        0x00, 0x13, // starting address: 19 (coil 20)
        0x00, 0x0A, // quantity of coils: 10
        0x02,       // byte count: 2
        0xCD,       // coils 27…20: 1100_1101
        0x01,       // coils 29, 28: 01, six padding bits
    ] => Request::WriteMultipleCoils(
        WriteCoils::new(19, Bits::from_values(&[true, false, true, true, false, false, true, true, true, false]))
            .unwrap(),
    ),
    |r| {
        let w = body!(r, Request::WriteMultipleCoils);
        assert_eq!((w.start(), w.quantity()), (19, 10));
        assert!(w.values().iter().eq([true, false, true, true, false, false, true, true, true, false]));
    }

    /// 3G3RX, slave 5: coils 7–12 ON, ON, ON, OFF, ON, OFF, with the byte count the spec calls
    /// for. The manual prints byte count 2 (`… 06 02 17 00`): see `bugs`.
    write_multiple_coils_request_3g3rx: Request [
        0x0F,       // function code: 0x0F Write Multiple Coils
        0x00, 0x06, // starting address: 6 (coil 7)
        0x00, 0x06, // quantity of coils: 6
        0x01,       // byte count: 1 = ceil(6 / 8)
        0x17,       // coils 12…7: 01_0111, two padding bits
    ] => Request::WriteMultipleCoils(
        WriteCoils::new(6, Bits::from_values(&[true, true, true, false, true, false])).unwrap(),
    ),
    |r| {
        let w = body!(r, Request::WriteMultipleCoils);
        assert_eq!((w.start(), w.quantity(), w.values().byte_len()), (6, 6, 1));
    }

    /// 3G3RX, slave 5: the answer (`05 0F 00 06 00 06 34 4C`).
    write_multiple_coils_response: Response [
        0x0F,       // function code: 0x0F Write Multiple Coils
        0x00, 0x06, // starting address: 6
        0x00, 0x06, // quantity of coils: 6
    ] => Response::WriteMultipleCoils(WrittenCoils::new(6, 6).unwrap()),
    |r| {
        let w = body!(r, Response::WriteMultipleCoils);
        assert_eq!((w.start(), w.quantity()), (6, 6));
    }

    // ── 0x10 Write Multiple Registers ────────────────────────────────────────────────────────

    /// SDP servo manual p.413, unit 1: 0x0BB8 to 0x0112, 0x0000 to 0x0113 (seed frame).
    write_multiple_registers_request: Request [
        0x10,       // function code: 0x10 Write Multiple Registers
        0x01, 0x12, // starting address: 0x0112
        0x00, 0x02, // quantity of registers: 2
        0x04,       // byte count: 4
        0x0B, 0xB8, // 0x0112: 3000
        0x00, 0x00, // 0x0113: 0
    ] => Request::WriteMultipleRegisters(
        WriteRegisters::new(0x0112, Registers::from_values(&[0x0BB8, 0x0000])).unwrap(),
    ),
    |r| {
        let w = body!(r, Request::WriteMultipleRegisters);
        assert_eq!((w.start(), w.quantity()), (0x0112, 2));
        assert!(w.values().iter().eq([3000, 0]));
    }

    /// 3G3RX p.4-173, slave 1: F002 = 300000 as two registers, high word first.
    write_multiple_registers_request_3g3rx: Request [
        0x10,       // function code: 0x10 Write Multiple Registers
        0x11, 0x02, // starting address: 0x1102 (F002)
        0x00, 0x02, // quantity of registers: 2
        0x04,       // byte count: 4
        0x00, 0x04, // 0x1102: 0x0004, high word of 300000
        0x93, 0xE0, // 0x1103: 0x93E0, low word
    ] => Request::WriteMultipleRegisters(
        WriteRegisters::new(0x1102, Registers::from_values(&[0x0004, 0x93E0])).unwrap(),
    ),
    |r| {
        let w = body!(r, Request::WriteMultipleRegisters);
        let v = w.values();
        assert_eq!((w.start(), u32::from(v.get(0).unwrap()) << 16 | u32::from(v.get(1).unwrap())), (0x1102, 300_000));
    }

    /// SDP servo manual p.413: the answer (seed frame).
    write_multiple_registers_response: Response [
        0x10,       // function code: 0x10 Write Multiple Registers
        0x01, 0x12, // starting address: 0x0112
        0x00, 0x02, // quantity of registers: 2
    ] => Response::WriteMultipleRegisters(WrittenRegisters::new(0x0112, 2).unwrap()),
    |r| {
        let w = body!(r, Response::WriteMultipleRegisters);
        assert_eq!((w.start(), w.quantity()), (0x0112, 2));
    }

    // ── 0x16 Mask Write Register ─────────────────────────────────────────────────────────────

    /// The spec's example (§6.16): register 4, AND 0x00F2, OR 0x0025.
    mask_write_register_request: Request [
        0x16,       // function code: 0x16 Mask Write Register
        0x00, 0x04, // reference address: 4
        0x00, 0xF2, // AND mask
        0x00, 0x25, // OR mask
    ] => Request::MaskWriteRegister(MaskWrite { address: 4, and_mask: 0x00F2, or_mask: 0x0025 }),
    |r| {
        let m = body!(r, Request::MaskWriteRegister);
        assert_eq!((m.address, m.and_mask, m.or_mask), (4, 0x00F2, 0x0025));
        assert_eq!(m.apply(0x0012), 0x0017, "the spec's worked example");
    }

    /// The echo of the request above.
    mask_write_register_response: Response [
        0x16,       // function code: 0x16 Mask Write Register
        0x00, 0x04, // reference address: 4
        0x00, 0xF2, // AND mask
        0x00, 0x25, // OR mask
    ] => Response::MaskWriteRegister(MaskWrite { address: 4, and_mask: 0x00F2, or_mask: 0x0025 }),
    |r| {
        let m = body!(r, Response::MaskWriteRegister);
        assert_eq!((m.address, m.and_mask, m.or_mask), (4, 0x00F2, 0x0025));
    }

    // ── 0x17 Read/Write Multiple Registers ───────────────────────────────────────────────────

    /// MX2 (PortDock), unit 1: write 50.00 Hz to 0x0000–0x0001, then read 0x1000–0x1001.
    read_write_multiple_registers_request: Request [
        0x17,       // function code: 0x17 Read/Write Multiple Registers
        0x10, 0x00, // read starting address: 0x1000
        0x00, 0x02, // quantity to read: 2
        0x00, 0x00, // write starting address: 0x0000
        0x00, 0x02, // quantity to write: 2
        0x04,       // write byte count: 4
        0x00, 0x00, // 0x0000: high word
        0x13, 0x88, // 0x0001: low word, 5000 (50.00 Hz)
    ] => Request::ReadWriteMultipleRegisters(
        ReadWriteRegisters::new(0x1000, 2, 0x0000, Registers::from_values(&[0x0000, 0x1388])).unwrap(),
    ),
    |r| {
        let rw = body!(r, Request::ReadWriteMultipleRegisters);
        assert_eq!((rw.read().start(), rw.read().quantity(), rw.write_start()), (0x1000, 2, 0));
        assert!(rw.values().iter().eq([0, 5000]));
    }

    /// An answer to the request above (illustrative: the manual prints no response).
    read_write_multiple_registers_response: Response [
        0x17,       // function code: 0x17 Read/Write Multiple Registers
        0x04,       // byte count: 4
        0x00, 0x00, // 0x1000: high word
        0x13, 0x88, // 0x1001: low word, 5000
    ] => Response::ReadWriteMultipleRegisters(RegisterValues::new(Registers::from_values(&[0x0000, 0x1388])).unwrap()),
    |r| {
        assert!(body!(r, Response::ReadWriteMultipleRegisters).values().iter().eq([0, 5000]));
    }
}
