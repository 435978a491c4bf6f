//! The code tables of the protocol: function codes, exception codes, diagnostic sub-functions,
//! MEI types and device-identification codes — each in one place, in hex, with its spec section.
//!
//! Spec: MODBUS Application Protocol V1.1b3 §5.1 (public function codes), §6.8.1 (diagnostic
//! sub-functions), §6.21 (read device identification), §7 (exception codes).
//!
//! Every table is total over its byte or word: a value the spec does not name maps to a
//! catch-all variant (`Custom`, `Vendor`, `Other`) and back to the same value, so that no
//! input is ever rejected for being unknown. The round trip is tested over all 256 values.

use core::fmt;

/// Generates a code enum with named variants, a catch-all, `from_*`/`value` conversions that
/// round-trip, and `name()`.
macro_rules! code_table {
    (
        $(#[$meta:meta])*
        pub enum $name:ident: $repr:ty {
            $( $(#[$vmeta:meta])* $variant:ident = $value:literal => $text:literal, )+
        }
        catch_all: $(#[$cmeta:meta])* $other:ident;
        from: $from:ident;
    ) => {
        $(#[$meta])*
        #[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
        pub enum $name {
            $( $(#[$vmeta])* $variant, )+
            $(#[$cmeta])*
            $other($repr),
        }

        impl $name {
            /// Every named code, in ascending order.
            pub const ALL: &'static [$name] = &[ $( $name::$variant, )+ ];

            /// The code for a raw value; values the spec does not name go to the catch-all.
            pub const fn $from(value: $repr) -> Self {
                match value {
                    $( $value => $name::$variant, )+
                    other => $name::$other(other),
                }
            }

            /// The raw value on the wire.
            pub const fn value(self) -> $repr {
                match self {
                    $( $name::$variant => $value, )+
                    $name::$other(v) => v,
                }
            }

            /// The spec's name, or `None` for a value the spec does not name.
            pub const fn name(self) -> Option<&'static str> {
                match self {
                    $( $name::$variant => Some($text), )+
                    $name::$other(_) => None,
                }
            }
        }

        impl From<$repr> for $name {
            fn from(value: $repr) -> Self {
                $name::$from(value)
            }
        }

        impl From<$name> for $repr {
            fn from(code: $name) -> Self {
                code.value()
            }
        }
    };
}

code_table! {
    /// A Modbus function code (MODBUS Application Protocol V1.1b3 §5.1, §6).
    ///
    /// Every public function code is named; any other byte is [`FunctionCode::Custom`]: user
    /// codes (0x41–0x48, 0x64–0x6E), vendor codes, and in responses the exception marker
    /// (a code with bit 7 set).
    pub enum FunctionCode: u8 {
        /// 0x01 Read Coils (§6.1).
        ReadCoils = 0x01 => "Read Coils",
        /// 0x02 Read Discrete Inputs (§6.2).
        ReadDiscreteInputs = 0x02 => "Read Discrete Inputs",
        /// 0x03 Read Holding Registers (§6.3).
        ReadHoldingRegisters = 0x03 => "Read Holding Registers",
        /// 0x04 Read Input Registers (§6.4).
        ReadInputRegisters = 0x04 => "Read Input Registers",
        /// 0x05 Write Single Coil (§6.5).
        WriteSingleCoil = 0x05 => "Write Single Coil",
        /// 0x06 Write Single Register (§6.6).
        WriteSingleRegister = 0x06 => "Write Single Register",
        /// 0x07 Read Exception Status, serial line only (§6.7).
        ReadExceptionStatus = 0x07 => "Read Exception Status",
        /// 0x08 Diagnostics, serial line only (§6.8).
        Diagnostics = 0x08 => "Diagnostics",
        /// 0x0B Get Comm Event Counter, serial line only (§6.9).
        GetCommEventCounter = 0x0B => "Get Comm Event Counter",
        /// 0x0C Get Comm Event Log, serial line only (§6.10).
        GetCommEventLog = 0x0C => "Get Comm Event Log",
        /// 0x0F Write Multiple Coils (§6.11).
        WriteMultipleCoils = 0x0F => "Write Multiple Coils",
        /// 0x10 Write Multiple Registers (§6.12).
        WriteMultipleRegisters = 0x10 => "Write Multiple Registers",
        /// 0x11 Report Server ID, serial line only (§6.13).
        ReportServerId = 0x11 => "Report Server ID",
        /// 0x14 Read File Record (§6.14).
        ReadFileRecord = 0x14 => "Read File Record",
        /// 0x15 Write File Record (§6.15).
        WriteFileRecord = 0x15 => "Write File Record",
        /// 0x16 Mask Write Register (§6.16).
        MaskWriteRegister = 0x16 => "Mask Write Register",
        /// 0x17 Read/Write Multiple Registers (§6.17).
        ReadWriteMultipleRegisters = 0x17 => "Read/Write Multiple Registers",
        /// 0x18 Read FIFO Queue (§6.18).
        ReadFifoQueue = 0x18 => "Read FIFO Queue",
        /// 0x2B Encapsulated Interface Transport (§6.19–6.21): MEI 0x0D CANopen General
        /// Reference, MEI 0x0E Read Device Identification.
        EncapsulatedInterface = 0x2B => "Encapsulated Interface Transport",
    }
    catch_all:
        /// Any other function code, carried as its raw byte.
        Custom;
    from: from_u8;
}

impl FunctionCode {
    /// The bit a server sets in the function code of an exception response (§7).
    pub const EXCEPTION_BIT: u8 = 0x80;

    /// Whether this code is defined by the public spec.
    pub const fn is_public(self) -> bool {
        !matches!(self, FunctionCode::Custom(_))
    }

    /// Whether a request with this code may be valid at all: codes 0x01–0x7F. Zero is not a
    /// function code, and codes with bit 7 set mark exception responses.
    pub const fn is_valid_request_code(self) -> bool {
        let v = self.value();
        v != 0 && v & Self::EXCEPTION_BIT == 0
    }

    /// Whether this code is in one of the two ranges the spec leaves to users, 65–72
    /// (0x41–0x48) and 100–110 (0x64–0x6E) (§5): no public code is there, and a vendor's
    /// device may implement its own. Every other code that is neither public nor user-defined
    /// is reserved or unassigned.
    pub const fn is_user_defined(self) -> bool {
        matches!(self.value(), 0x41..=0x48 | 0x64..=0x6E)
    }

    /// Whether a request with this code writes data, the only kind a broadcast should carry
    /// (MODBUS over Serial Line V1.02 §2.1): 0x05, 0x06, 0x0F, 0x10, 0x15, 0x16 and 0x17
    /// Read/Write Multiple Registers, which writes before it reads (§6.17).
    ///
    /// The one rule of "writes, by function code": which broadcasts a slave serves and a
    /// gateway forwards, and which refusals a read-only gateway or role is named for. 0x08
    /// Diagnostics is not a write, though some of its sub-functions restart or silence.
    pub const fn is_write(self) -> bool {
        matches!(
            self,
            FunctionCode::WriteSingleCoil
                | FunctionCode::WriteSingleRegister
                | FunctionCode::WriteMultipleCoils
                | FunctionCode::WriteMultipleRegisters
                | FunctionCode::WriteFileRecord
                | FunctionCode::MaskWriteRegister
                | FunctionCode::ReadWriteMultipleRegisters
        )
    }
}

/// `0x03 Read Holding Registers`, or `0x41 (custom)`.
impl fmt::Display for FunctionCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.name() {
            Some(name) => write!(f, "0x{:02X} {name}", self.value()),
            None => write!(f, "0x{:02X} (custom)", self.value()),
        }
    }
}

code_table! {
    /// An exception code returned by a server (MODBUS Application Protocol V1.1b3 §7).
    ///
    /// The nine codes of V1.1b3 are named. Any other byte — 0x07 and 0x09 from older lists, the
    /// Hitachi/Omron inverters' 0x21–0x27 — is kept as [`ExceptionCode::Vendor`] and shown as a
    /// vendor code: never rejected.
    pub enum ExceptionCode: u8 {
        /// 0x01: the function code is not supported by the server.
        IllegalFunction = 0x01 => "Illegal Function",
        /// 0x02: the data address (or address + quantity) is not allowed.
        IllegalDataAddress = 0x02 => "Illegal Data Address",
        /// 0x03: a value in the request is not allowed (e.g. a quantity out of range).
        IllegalDataValue = 0x03 => "Illegal Data Value",
        /// 0x04: an unrecoverable error while performing the action.
        ServerDeviceFailure = 0x04 => "Server Device Failure",
        /// 0x05: accepted, but it will take a long time; poll for completion.
        Acknowledge = 0x05 => "Acknowledge",
        /// 0x06: the server is busy with a long-duration command; retry later.
        ServerDeviceBusy = 0x06 => "Server Device Busy",
        /// 0x08: a parity error in extended memory (file records).
        MemoryParityError = 0x08 => "Memory Parity Error",
        /// 0x0A: a gateway could not allocate a path to the target.
        GatewayPathUnavailable = 0x0A => "Gateway Path Unavailable",
        /// 0x0B: a gateway got no response from the target device.
        GatewayTargetDeviceFailedToRespond = 0x0B => "Gateway Target Device Failed to Respond",
    }
    catch_all:
        /// A code the spec does not define, such as a drive's 0x21 "value out of range".
        Vendor;
    from: from_u8;
}

/// `0x02 Illegal Data Address`, or `0x21 (vendor-specific)`.
impl fmt::Display for ExceptionCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.name() {
            Some(name) => write!(f, "0x{:02X} {name}", self.value()),
            None => write!(f, "0x{:02X} (vendor-specific)", self.value()),
        }
    }
}

code_table! {
    /// A sub-function of 0x08 Diagnostics (MODBUS Application Protocol V1.1b3 §6.8.1).
    pub enum DiagnosticCode: u16 {
        /// 0x00: echo the request data.
        ReturnQueryData = 0x0000 => "Return Query Data",
        /// 0x01: restart the port, clear counters (data 0xFF00 also clears the event log);
        /// the only way out of listen-only mode.
        RestartCommunications = 0x0001 => "Restart Communications Option",
        /// 0x02: return the 16-bit diagnostic register.
        ReturnDiagnosticRegister = 0x0002 => "Return Diagnostic Register",
        /// 0x03: change the ASCII end-of-message delimiter to the data's high byte.
        ChangeAsciiDelimiter = 0x0003 => "Change ASCII Input Delimiter",
        /// 0x04: stop answering until 0x01; no response is sent.
        ForceListenOnly = 0x0004 => "Force Listen Only Mode",
        /// 0x0A: clear all counters and the diagnostic register.
        ClearCounters = 0x000A => "Clear Counters and Diagnostic Register",
        /// 0x0B: messages the server saw on the bus.
        BusMessageCount = 0x000B => "Return Bus Message Count",
        /// 0x0C: CRC errors the server saw.
        BusCommErrorCount = 0x000C => "Return Bus Communication Error Count",
        /// 0x0D: exception responses the server sent.
        BusExceptionErrorCount = 0x000D => "Return Bus Exception Error Count",
        /// 0x0E: messages addressed to the server (or broadcast) that it processed.
        ServerMessageCount = 0x000E => "Return Server Message Count",
        /// 0x0F: messages to the server that it did not answer.
        ServerNoResponseCount = 0x000F => "Return Server No Response Count",
        /// 0x10: negative acknowledgements the server sent.
        ServerNakCount = 0x0010 => "Return Server NAK Count",
        /// 0x11: "server busy" exceptions the server sent.
        ServerBusyCount = 0x0011 => "Return Server Busy Count",
        /// 0x12: messages lost to character overrun.
        BusCharacterOverrunCount = 0x0012 => "Return Bus Character Overrun Count",
        /// 0x14: clear the overrun counter and flag.
        ClearOverrunCounter = 0x0014 => "Clear Overrun Counter and Flag",
    }
    catch_all:
        /// A sub-function the spec does not define here (0x13, 0x15, vendor ones).
        Other;
    from: from_u16;
}

/// `0x000B Return Bus Message Count`.
impl fmt::Display for DiagnosticCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.name() {
            Some(name) => write!(f, "0x{:04X} {name}", self.value()),
            None => write!(f, "0x{:04X} (unknown sub-function)", self.value()),
        }
    }
}

code_table! {
    /// The MEI type of a 0x2B Encapsulated Interface Transport PDU (§6.19).
    pub enum MeiType: u8 {
        /// 0x0D CANopen General Reference (§6.20).
        CanOpenGeneralReference = 0x0D => "CANopen General Reference",
        /// 0x0E Read Device Identification (§6.21).
        ReadDeviceIdentification = 0x0E => "Read Device Identification",
    }
    catch_all:
        /// Any other MEI type, carried as raw bytes.
        Other;
    from: from_u8;
}

code_table! {
    /// The Read Device ID code of a 0x2B/0x0E request (§6.21).
    pub enum ReadDeviceIdCode: u8 {
        /// 0x01: the basic objects 0x00–0x02, as a stream.
        Basic = 0x01 => "basic",
        /// 0x02: the regular objects 0x03–0x7F, as a stream.
        Regular = 0x02 => "regular",
        /// 0x03: the extended objects 0x80–0xFF, as a stream.
        Extended = 0x03 => "extended",
        /// 0x04: one specific object.
        Specific = 0x04 => "specific",
    }
    catch_all:
        /// Any other value; invalid in a request (answered with exception 0x03).
        Other;
    from: from_u8;
}

impl ReadDeviceIdCode {
    /// The lowest object id this access category covers.
    pub const fn first_object(self) -> u8 {
        match self {
            ReadDeviceIdCode::Regular => 0x03,
            ReadDeviceIdCode::Extended => 0x80,
            _ => 0x00,
        }
    }

    /// The highest object id this access category covers.
    pub const fn last_object(self) -> u8 {
        match self {
            ReadDeviceIdCode::Basic => 0x02,
            ReadDeviceIdCode::Regular => 0x7F,
            _ => 0xFF,
        }
    }
}

/// The conformity level byte of a Read Device Identification response (§6.21): the highest
/// category of objects the device has (0x01 basic, 0x02 regular, 0x03 extended), with bit 7
/// set when it also supports individual access (code 0x04).
pub mod conformity {
    use super::ReadDeviceIdCode;

    /// Bit 7: individual access (code 0x04) is supported as well as stream access.
    pub const INDIVIDUAL_ACCESS: u8 = 0x80;
    /// The bits that give the category.
    pub const CATEGORY_MASK: u8 = 0x7F;

    /// The level byte for a device whose objects reach `category`. A `category` that is not
    /// one of basic, regular or extended is taken as basic.
    pub const fn level(category: ReadDeviceIdCode, individual_access: bool) -> u8 {
        let category = match category {
            ReadDeviceIdCode::Regular => 0x02,
            ReadDeviceIdCode::Extended => 0x03,
            _ => 0x01,
        };
        if individual_access { category | INDIVIDUAL_ACCESS } else { category }
    }

    /// The category a level byte names: basic, regular or extended, or `None` for a level the
    /// spec does not define.
    pub const fn category(level: u8) -> Option<ReadDeviceIdCode> {
        match level & CATEGORY_MASK {
            0x01 => Some(ReadDeviceIdCode::Basic),
            0x02 => Some(ReadDeviceIdCode::Regular),
            0x03 => Some(ReadDeviceIdCode::Extended),
            _ => None,
        }
    }

    /// Whether a level byte says individual access is supported.
    pub const fn individual_access(level: u8) -> bool {
        level & INDIVIDUAL_ACCESS != 0
    }
}

/// The device identification objects of the basic and regular categories (§6.21).
pub mod device_object {
    /// 0x00 VendorName (basic, mandatory).
    pub const VENDOR_NAME: u8 = 0x00;
    /// 0x01 ProductCode (basic, mandatory).
    pub const PRODUCT_CODE: u8 = 0x01;
    /// 0x02 MajorMinorRevision (basic, mandatory).
    pub const MAJOR_MINOR_REVISION: u8 = 0x02;
    /// 0x03 VendorUrl (regular).
    pub const VENDOR_URL: u8 = 0x03;
    /// 0x04 ProductName (regular).
    pub const PRODUCT_NAME: u8 = 0x04;
    /// 0x05 ModelName (regular).
    pub const MODEL_NAME: u8 = 0x05;
    /// 0x06 UserApplicationName (regular).
    pub const USER_APPLICATION_NAME: u8 = 0x06;

    /// The spec's name of a standard object, or `None` for a reserved or extended one.
    pub const fn name(id: u8) -> Option<&'static str> {
        match id {
            VENDOR_NAME => Some("VendorName"),
            PRODUCT_CODE => Some("ProductCode"),
            MAJOR_MINOR_REVISION => Some("MajorMinorRevision"),
            VENDOR_URL => Some("VendorUrl"),
            PRODUCT_NAME => Some("ProductName"),
            MODEL_NAME => Some("ModelName"),
            USER_APPLICATION_NAME => Some("UserApplicationName"),
            _ => None,
        }
    }
}

/// Unit (slave) addresses on a serial line (MODBUS over Serial Line V1.02 §2.2).
pub mod unit {
    /// Address 0: every slave executes the request and none answers.
    pub const BROADCAST: u8 = 0;
    /// The lowest individual slave address.
    pub const MIN: u8 = 1;
    /// The highest individual slave address; 248–255 are reserved (and some drives use them
    /// for group broadcasts, so a master does not reject them).
    pub const MAX: u8 = 247;
    /// The unit id a Modbus/TCP client uses for a directly connected server (Messaging
    /// Implementation Guide V1.0b, p. 23).
    pub const TCP_DIRECT: u8 = 0xFF;

    /// Whether a request to `unit` is a broadcast: address 0 on a serial framing (RTU or
    /// ASCII, also when carried over TCP). Over Modbus/TCP (MBAP) unit 0 is an ordinary
    /// address (Messaging Implementation Guide V1.0b §4.4.2.1: a server answers it).
    pub const fn is_broadcast(unit: u8, serial: bool) -> bool {
        serial && unit == BROADCAST
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::string::ToString;

    #[test]
    fn only_unit_zero_on_a_serial_framing_is_a_broadcast_over_all_256_values() {
        for v in 0..=u8::MAX {
            assert_eq!(unit::is_broadcast(v, true), v == 0x00, "unit {v:#04x} on a serial line");
            assert!(!unit::is_broadcast(v, false), "unit {v:#04x} over Modbus/TCP");
        }
    }

    #[test]
    fn conformity_levels_read_back_their_category_and_access_over_all_256_values() {
        for v in 0..=u8::MAX {
            let category = conformity::category(v);
            assert_eq!(category.is_some(), matches!(v & 0x7F, 0x01..=0x03), "{v:#04x}");
            assert_eq!(conformity::individual_access(v), v >= 0x80, "{v:#04x}");
            if let Some(category) = category {
                assert_eq!(conformity::level(category, v >= 0x80), v, "{v:#04x}");
            }
        }
        assert_eq!(conformity::level(ReadDeviceIdCode::Basic, true), 0x81);
        assert_eq!(conformity::level(ReadDeviceIdCode::Regular, true), 0x82);
        assert_eq!(conformity::level(ReadDeviceIdCode::Extended, false), 0x03);
    }

    #[test]
    fn each_access_category_covers_its_object_ids() {
        let span = |c: ReadDeviceIdCode| (c.first_object(), c.last_object());
        assert_eq!(span(ReadDeviceIdCode::Basic), (0x00, 0x02));
        assert_eq!(span(ReadDeviceIdCode::Regular), (0x03, 0x7F));
        assert_eq!(span(ReadDeviceIdCode::Extended), (0x80, 0xFF));
    }

    #[test]
    fn function_codes_round_trip_over_all_256_values() {
        for v in 0..=u8::MAX {
            let code = FunctionCode::from_u8(v);
            assert_eq!(code.value(), v);
            assert_eq!(code.is_public(), code.name().is_some());
        }
    }

    #[test]
    fn the_nineteen_public_function_codes_are_named_in_hex() {
        let named: std::vec::Vec<u8> = FunctionCode::ALL.iter().map(|c| c.value()).collect();
        assert_eq!(
            named,
            [
                0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08, 0x0B, 0x0C, 0x0F, 0x10, 0x11, 0x14, 0x15, 0x16, 0x17,
                0x18, 0x2B
            ]
        );
    }

    #[test]
    fn the_writes_are_05_06_0f_10_15_16_and_17_over_all_256_values() {
        // Hex, from the table in §5.1: the "write" rows, and 0x17 that writes then reads.
        const WRITES: [u8; 7] = [0x05, 0x06, 0x0F, 0x10, 0x15, 0x16, 0x17];
        for v in 0..=u8::MAX {
            assert_eq!(FunctionCode::from_u8(v).is_write(), WRITES.contains(&v), "{v:#04x}");
        }
        assert!(FunctionCode::ReadWriteMultipleRegisters.is_write());
        assert!(!FunctionCode::Diagnostics.is_write() && !FunctionCode::ReadFifoQueue.is_write());
    }

    #[test]
    fn request_codes_exclude_zero_and_the_exception_bit() {
        assert!(!FunctionCode::from_u8(0x00).is_valid_request_code());
        assert!(FunctionCode::from_u8(0x41).is_valid_request_code());
        assert!(FunctionCode::from_u8(0x7F).is_valid_request_code());
        assert!(!FunctionCode::from_u8(0x83).is_valid_request_code());
    }

    #[test]
    fn user_defined_codes_are_65_to_72_and_100_to_110_valid_requests_and_never_public_over_all_256_values() {
        for v in 0..=u8::MAX {
            let code = FunctionCode::from_u8(v);
            assert_eq!(code.is_user_defined(), (65..=72).contains(&v) || (100..=110).contains(&v), "{v}");
            if code.is_user_defined() {
                assert!(code.is_valid_request_code() && !code.is_public(), "{v}");
            }
        }
    }

    #[test]
    fn exception_codes_round_trip_and_gateway_codes_are_0a_and_0b() {
        for v in 0..=u8::MAX {
            assert_eq!(ExceptionCode::from_u8(v).value(), v);
        }
        assert_eq!(ExceptionCode::GatewayPathUnavailable.value(), 0x0A);
        assert_eq!(ExceptionCode::GatewayTargetDeviceFailedToRespond.value(), 0x0B);
        let named: std::vec::Vec<u8> = ExceptionCode::ALL.iter().map(|c| c.value()).collect();
        assert_eq!(named, [0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x08, 0x0A, 0x0B]);
    }

    #[test]
    fn codes_outside_the_spec_are_passed_through_as_vendor_codes() {
        assert_eq!(ExceptionCode::from_u8(0x07), ExceptionCode::Vendor(0x07));
        assert_eq!(ExceptionCode::from_u8(0x21).to_string(), "0x21 (vendor-specific)");
        assert_eq!(ExceptionCode::from_u8(0x02).to_string(), "0x02 Illegal Data Address");
        assert_eq!(FunctionCode::from_u8(0x41).to_string(), "0x41 (custom)");
    }

    #[test]
    fn diagnostic_and_mei_codes_round_trip() {
        for v in 0..=u16::from(u8::MAX) {
            assert_eq!(DiagnosticCode::from_u16(v).value(), v);
        }
        assert_eq!(DiagnosticCode::from_u16(0xFFFF).value(), 0xFFFF);
        for v in 0..=u8::MAX {
            assert_eq!(MeiType::from_u8(v).value(), v);
            assert_eq!(ReadDeviceIdCode::from_u8(v).value(), v);
        }
        assert_eq!(DiagnosticCode::BusCharacterOverrunCount.value(), 0x12);
        assert_eq!(DiagnosticCode::ClearOverrunCounter.value(), 0x14);
    }
}
