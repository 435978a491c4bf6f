//! Goldens of file records, the FIFO, encapsulated interfaces, a custom code and exception
//! responses: 0x14, 0x15, 0x18, 0x2B (spec §6.14, §6.15, §6.18–6.21, §7).

use super::*;
use crate::codes::{ExceptionCode, MeiType, ReadDeviceIdCode};

/// A 0x2B/0x0E request.
fn read_device_id(code: ReadDeviceIdCode, object_id: u8) -> Request<'static> {
    Request::EncapsulatedInterface(MeiRequest::ReadDeviceId(ReadDeviceId::new(code, object_id).unwrap()))
}

/// An exception response, built as a caller would.
fn exception(function: FunctionCode, code: ExceptionCode) -> Response<'static> {
    Response::Exception(ExceptionResponse::new(function, code).unwrap())
}

goldens! {
    // ── 0x14 Read File Record ────────────────────────────────────────────────────────────────

    /// The spec's example (§6.14): two sub-requests.
    read_file_record_request: Request [
        0x14,       // function code: 0x14 Read File Record
        0x0E,       // byte count: 14, two sub-requests of 7
        0x06,       // sub-request 1: reference type 6
        0x00, 0x04, //   file number: 4
        0x00, 0x01, //   record number: 1
        0x00, 0x02, //   record length: 2 registers
        0x06,       // sub-request 2: reference type 6
        0x00, 0x03, //   file number: 3
        0x00, 0x09, //   record number: 9
        0x00, 0x02, //   record length: 2 registers
    ] => Request::ReadFileRecord(
        FileRecordReads::new(&[
            FileRecordRef { file: 4, record: 1, length: 2 },
            FileRecordRef { file: 3, record: 9, length: 2 },
        ])
        .unwrap(),
    ),
    |r| {
        let reads = body!(r, Request::ReadFileRecord);
        assert_eq!(reads.len(), 2);
        assert_eq!(reads.get(1), Some(FileRecordRef { file: 3, record: 9, length: 2 }));
        assert_eq!(reads.get(2), None);
    }

    /// The spec's example (§6.14): one register list per sub-request.
    read_file_record_response: Response [
        0x14,       // function code: 0x14 Read File Record
        0x0C,       // response data length: 12
        0x05,       // sub-response 1: length 5 (reference type + 2 registers)
        0x06,       //   reference type 6
        0x0D, 0xFE, //   register: 0x0DFE
        0x00, 0x20, //   register: 0x0020
        0x05,       // sub-response 2: length 5
        0x06,       //   reference type 6
        0x33, 0xCD, //   register: 0x33CD
        0x00, 0x40, //   register: 0x0040
    ] => Response::ReadFileRecord(
        FileSubResponses::new(const {
            &[Registers::from_values(&[0x0DFE, 0x0020]), Registers::from_values(&[0x33CD, 0x0040])]
        })
        .unwrap(),
    ),
    |r| {
        let subs = body!(r, Response::ReadFileRecord);
        assert_eq!(subs.len(), 2);
        let mut it = subs.iter();
        assert!(it.next().unwrap().iter().eq([0x0DFE, 0x0020]));
        assert!(it.next().unwrap().iter().eq([0x33CD, 0x0040]));
    }

    // ── 0x15 Write File Record ───────────────────────────────────────────────────────────────

    /// The spec's example (§6.15): three registers to file 4 from record 7.
    write_file_record_request: Request [
        0x15,       // function code: 0x15 Write File Record
        0x0D,       // request data length: 13
        0x06,       // sub-request 1: reference type 6
        0x00, 0x04, //   file number: 4
        0x00, 0x07, //   record number: 7
        0x00, 0x03, //   record length: 3 registers
        0x06, 0xAF, //   0x06AF
        0x04, 0xBE, //   0x04BE
        0x10, 0x0D, //   0x100D
    ] => Request::WriteFileRecord(
        FileRecordWrites::new(const {
            &[FileRecordWrite { file: 4, record: 7, data: Registers::from_values(&[0x06AF, 0x04BE, 0x100D]) }]
        })
        .unwrap(),
    ),
    |r| {
        let writes = body!(r, Request::WriteFileRecord);
        assert_eq!(writes.len(), 1);
        let w = writes.iter().next().unwrap();
        assert_eq!((w.file, w.record), (4, 7));
        assert!(w.data.iter().eq([0x06AF, 0x04BE, 0x100D]));
    }

    /// The echo of the request above.
    write_file_record_response: Response [
        0x15,       // function code: 0x15 Write File Record
        0x0D,       // response data length: 13
        0x06,       // sub-request 1: reference type 6
        0x00, 0x04, //   file number: 4
        0x00, 0x07, //   record number: 7
        0x00, 0x03, //   record length: 3 registers
        0x06, 0xAF, //   0x06AF
        0x04, 0xBE, //   0x04BE
        0x10, 0x0D, //   0x100D
    ] => Response::WriteFileRecord(
        FileRecordWrites::new(const {
            &[FileRecordWrite { file: 4, record: 7, data: Registers::from_values(&[0x06AF, 0x04BE, 0x100D]) }]
        })
        .unwrap(),
    ),
    |r| {
        let w = body!(r, Response::WriteFileRecord).iter().next().unwrap();
        assert_eq!((w.file, w.record, w.data.len()), (4, 7, 3));
    }

    // ── 0x18 Read FIFO Queue ─────────────────────────────────────────────────────────────────

    /// The spec's example (§6.18): the FIFO at 0x04DE.
    read_fifo_queue_request: Request [
        0x18,       // function code: 0x18 Read FIFO Queue
        0x04, 0xDE, // FIFO pointer address: 0x04DE
    ] => Request::ReadFifoQueue(ReadFifo { address: 0x04DE }),
    |r| {
        assert_eq!(body!(r, Request::ReadFifoQueue).address, 0x04DE);
    }

    /// The spec's example (§6.18): two queued values.
    read_fifo_queue_response: Response [
        0x18,       // function code: 0x18 Read FIFO Queue
        0x00, 0x06, // byte count: 6 (the count and two values)
        0x00, 0x02, // FIFO count: 2
        0x01, 0xB8, // value: 440
        0x12, 0x84, // value: 4740
    ] => Response::ReadFifoQueue(FifoValues::new(Registers::from_values(&[0x01B8, 0x1284])).unwrap()),
    |r| {
        assert!(body!(r, Response::ReadFifoQueue).values().iter().eq([440, 4740]));
    }

    // ── 0x2B / 0x0E Read Device Identification ───────────────────────────────────────────────

    /// Stream the basic objects from the first.
    read_device_id_basic_request: Request [
        0x2B, // function code: 0x2B Encapsulated Interface Transport
        0x0E, // MEI type: 0x0E Read Device Identification
        0x01, // read device id code: 0x01 basic stream
        0x00, // object id: 0x00 VendorName
    ] => read_device_id(ReadDeviceIdCode::Basic, 0),
    |r| {
        let MeiRequest::ReadDeviceId(q) = body!(r, Request::EncapsulatedInterface) else { panic!("{r:?}") };
        assert_eq!((q.code(), q.object_id()), (ReadDeviceIdCode::Basic, 0));
    }

    /// The first part of the basic stream: two objects, more follow from object 2.
    read_device_id_basic_response: Response [
        0x2B,                         // function code: 0x2B Encapsulated Interface Transport
        0x0E,                         // MEI type: 0x0E Read Device Identification
        0x01,                         // read device id code: 0x01 basic stream
        0x01,                         // conformity level: basic, stream access only
        0xFF,                         // more follows: 0xFF, yes
        0x02,                         // next object id: 0x02 MajorMinorRevision
        0x02,                         // number of objects: 2
        0x00,                         // object 0x00 VendorName
        0x05,                         //   length: 5
        b'O', b'm', b'r', b'o', b'n', //   "Omron"
        0x01,                         // object 0x01 ProductCode
        0x05,                         //   length: 5
        b'3', b'G', b'3', b'R', b'X', //   "3G3RX"
    ] => Response::EncapsulatedInterface(MeiResponse::ReadDeviceId(
        DeviceIdentification::new(
            ReadDeviceIdCode::Basic,
            0x01,
            true,
            0x02,
            DeviceObjects::new(&[
                DeviceObject { id: 0x00, value: b"Omron" },
                DeviceObject { id: 0x01, value: b"3G3RX" },
            ])
            .unwrap(),
        )
        .unwrap(),
    )),
    |r| {
        let MeiResponse::ReadDeviceId(id) = body!(r, Response::EncapsulatedInterface) else { panic!("{r:?}") };
        assert_eq!((id.code(), id.conformity()), (ReadDeviceIdCode::Basic, 0x01));
        assert_eq!((id.more_follows(), id.next_object_id()), (true, 0x02));
        let objects = id.objects();
        assert_eq!(objects.len(), 2);
        assert!(objects.iter().eq([DeviceObject { id: 0, value: b"Omron" }, DeviceObject { id: 1, value: b"3G3RX" }]));
    }

    /// Ask for one specific object: 0x02 MajorMinorRevision.
    read_device_id_specific_request: Request [
        0x2B, // function code: 0x2B Encapsulated Interface Transport
        0x0E, // MEI type: 0x0E Read Device Identification
        0x04, // read device id code: 0x04 one specific object
        0x02, // object id: 0x02 MajorMinorRevision
    ] => read_device_id(ReadDeviceIdCode::Specific, 2),
    |r| {
        let MeiRequest::ReadDeviceId(q) = body!(r, Request::EncapsulatedInterface) else { panic!("{r:?}") };
        assert_eq!((q.code(), q.object_id()), (ReadDeviceIdCode::Specific, 2));
    }

    /// The one object asked for.
    read_device_id_specific_response: Response [
        0x2B,                   // function code: 0x2B Encapsulated Interface Transport
        0x0E,                   // MEI type: 0x0E Read Device Identification
        0x04,                   // read device id code: 0x04 one specific object
        0x81,                   // conformity level: basic, stream and individual access
        0x00,                   // more follows: 0x00, no
        0x00,                   // next object id: 0x00 (none)
        0x01,                   // number of objects: 1
        0x02,                   // object 0x02 MajorMinorRevision
        0x04,                   //   length: 4
        b'1', b'.', b'1', b'0', //   "1.10"
    ] => Response::EncapsulatedInterface(MeiResponse::ReadDeviceId(
        DeviceIdentification::new(
            ReadDeviceIdCode::Specific,
            0x81,
            false,
            0x00,
            DeviceObjects::new(&[DeviceObject { id: 0x02, value: b"1.10" }]).unwrap(),
        )
        .unwrap(),
    )),
    |r| {
        let MeiResponse::ReadDeviceId(id) = body!(r, Response::EncapsulatedInterface) else { panic!("{r:?}") };
        assert_eq!((id.code(), id.conformity()), (ReadDeviceIdCode::Specific, 0x81));
        assert_eq!((id.more_follows(), id.next_object_id()), (false, 0x00));
        assert!(id.objects().iter().eq([DeviceObject { id: 2, value: b"1.10" }]));
    }

    // ── 0x2B / 0x0D CANopen General Reference (raw) ──────────────────────────────────────────

    /// A CANopen General Reference request: the data after the MEI type is carried raw.
    canopen_general_reference_request: Request [
        0x2B,             // function code: 0x2B Encapsulated Interface Transport
        0x0D,             // MEI type: 0x0D CANopen General Reference
        0x00, 0x60, 0x41, // CANopen data, uninterpreted
    ] => Request::EncapsulatedInterface(MeiRequest::Other(
        RawMei::new(MeiType::CanOpenGeneralReference, &[0x00, 0x60, 0x41]).unwrap(),
    )),
    |r| {
        let MeiRequest::Other(raw) = body!(r, Request::EncapsulatedInterface) else { panic!("{r:?}") };
        assert_eq!((raw.mei_type(), raw.data()), (MeiType::CanOpenGeneralReference, &[0x00, 0x60, 0x41][..]));
    }

    /// A CANopen General Reference response, raw.
    canopen_general_reference_response: Response [
        0x2B,                         // function code: 0x2B Encapsulated Interface Transport
        0x0D,                         // MEI type: 0x0D CANopen General Reference
        0x00, 0x60, 0x41, 0x37, 0x02, // CANopen data, uninterpreted
    ] => Response::EncapsulatedInterface(MeiResponse::Other(
        RawMei::new(MeiType::CanOpenGeneralReference, &[0x00, 0x60, 0x41, 0x37, 0x02]).unwrap(),
    )),
    |r| {
        let MeiResponse::Other(raw) = body!(r, Response::EncapsulatedInterface) else { panic!("{r:?}") };
        assert_eq!((raw.mei_type(), raw.data().len()), (MeiType::CanOpenGeneralReference, 5));
    }

    // ── A custom function code ───────────────────────────────────────────────────────────────

    /// User-defined code 0x41: the data is carried raw.
    custom_request: Request [
        0x41,             // function code: 0x41, user-defined
        0x01, 0x02, 0x03, // data, uninterpreted
    ] => Request::Custom(Custom::new(0x41, &[0x01, 0x02, 0x03]).unwrap()),
    |r| {
        let c = body!(r, Request::Custom);
        assert_eq!((c.function(), c.data()), (0x41, &[0x01, 0x02, 0x03][..]));
    }

    /// User-defined code 0x41: a response with no data at all.
    custom_response: Response [
        0x41, // function code: 0x41, user-defined
    ] => Response::Custom(Custom::new(0x41, &[]).unwrap()),
    |r| {
        let c = body!(r, Response::Custom);
        assert_eq!((c.function(), c.data()), (0x41, &[][..]));
    }

    // ── Exception responses ──────────────────────────────────────────────────────────────────

    /// A read of coils past the end of the map.
    exception_illegal_data_address: Response [
        0x81, // function code: 0x01 Read Coils + 0x80
        0x02, // exception code: 0x02 Illegal Data Address
    ] => exception(FunctionCode::ReadCoils, ExceptionCode::IllegalDataAddress),
    |r| {
        let e = body!(r, Response::Exception);
        assert_eq!((e.function(), e.code()), (FunctionCode::ReadCoils, ExceptionCode::IllegalDataAddress));
        assert_eq!(r.exception(), Some(*e));
    }

    /// RKC COM-ML p.143, slave 1: loopback refused (`01 88 03 06 01`).
    exception_illegal_data_value_to_diagnostics: Response [
        0x88, // function code: 0x08 Diagnostics + 0x80
        0x03, // exception code: 0x03 Illegal Data Value
    ] => exception(FunctionCode::Diagnostics, ExceptionCode::IllegalDataValue),
    |r| {
        let e = body!(r, Response::Exception);
        assert_eq!((e.function(), e.code()), (FunctionCode::Diagnostics, ExceptionCode::IllegalDataValue));
    }

    /// 3G3RX / SJ700 vendor code 21h: the value written is outside the inverter's range.
    exception_vendor_code_21: Response [
        0x86, // function code: 0x06 Write Single Register + 0x80
        0x21, // exception code: 0x21, vendor-specific
    ] => exception(FunctionCode::WriteSingleRegister, ExceptionCode::Vendor(0x21)),
    |r| {
        let e = body!(r, Response::Exception);
        assert_eq!((e.function(), e.code()), (FunctionCode::WriteSingleRegister, ExceptionCode::Vendor(0x21)));
        assert_eq!(e.code().name(), None);
    }

    /// A gateway that has no path to the target.
    exception_gateway_path_unavailable: Response [
        0x83, // function code: 0x03 Read Holding Registers + 0x80
        0x0A, // exception code: 0x0A Gateway Path Unavailable
    ] => exception(FunctionCode::ReadHoldingRegisters, ExceptionCode::GatewayPathUnavailable),
    |r| {
        assert_eq!(body!(r, Response::Exception).code(), ExceptionCode::GatewayPathUnavailable);
    }

    /// A gateway whose target did not answer.
    exception_gateway_target_failed_to_respond: Response [
        0x90, // function code: 0x10 Write Multiple Registers + 0x80
        0x0B, // exception code: 0x0B Gateway Target Device Failed to Respond
    ] => exception(FunctionCode::WriteMultipleRegisters, ExceptionCode::GatewayTargetDeviceFailedToRespond),
    |r| {
        let e = body!(r, Response::Exception);
        assert_eq!(e.function(), FunctionCode::WriteMultipleRegisters);
        assert_eq!(e.code(), ExceptionCode::GatewayTargetDeviceFailedToRespond);
    }

    /// A refusal of the custom code 0x41.
    exception_to_a_custom_code: Response [
        0xC1, // function code: 0x41 + 0x80
        0x01, // exception code: 0x01 Illegal Function
    ] => exception(FunctionCode::Custom(0x41), ExceptionCode::IllegalFunction),
    |r| {
        let e = body!(r, Response::Exception);
        assert_eq!((e.function(), e.code()), (FunctionCode::Custom(0x41), ExceptionCode::IllegalFunction));
    }
}
