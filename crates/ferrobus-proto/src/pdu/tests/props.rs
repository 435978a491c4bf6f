//! Property tests: `parse(emit(x)) == x` for every function code, and bytes that must never
//! make parse or `wire_len` panic.
//!
//! Values borrow their data, so proptest generates owned models; a model's `with` builds the
//! borrowed value through the constructors and hands it to a check. Quantities span their
//! whole range (with the ends drawn more often), and lists of sub-requests or objects are cut
//! to what fits in one PDU.

use proptest::collection::vec as vec_of;
use proptest::prelude::*;
use proptest::sample::{Index, select};

use super::*;
use crate::codes::{DiagnosticCode, ExceptionCode, MeiType, ReadDeviceIdCode};

// ── Models ──────────────────────────────────────────────────────────────────────────────────

/// An owned request or response that can build its borrowed value.
trait Model: Clone + core::fmt::Debug {
    fn with<R>(&self, f: impl FnOnce(Pdu<'_>) -> R) -> R;
}

/// 0x08 data: one word (every named sub-function but 0x00) or any bytes.
#[derive(Clone, Debug)]
enum DiagModel {
    Word(DiagnosticCode, u16),
    Data(DiagnosticCode, Vec<u8>),
}

impl DiagModel {
    fn build(&self) -> Diagnostic<'_> {
        match self {
            DiagModel::Word(code, word) => Diagnostic::with_word(*code, *word),
            DiagModel::Data(code, data) => Diagnostic::with_data(*code, data).unwrap(),
        }
    }
}

/// One 0x15 sub-request: file, record, registers.
type FileWriteModel = (u16, u16, Vec<u16>);

fn file_writes(subs: &[FileWriteModel]) -> Vec<FileRecordWrite<'_>> {
    subs.iter()
        .map(|(file, record, data)| FileRecordWrite {
            file: *file,
            record: *record,
            data: Registers::from_values(data),
        })
        .collect()
}

#[derive(Clone, Debug)]
enum RequestModel {
    ReadBits { function: FunctionCode, start: u16, quantity: u16 },
    ReadRegisters { function: FunctionCode, start: u16, quantity: u16 },
    WriteCoil(WriteCoil),
    WriteRegister(WriteRegister),
    NoData(FunctionCode),
    Diagnostic(DiagModel),
    WriteCoils { start: u16, values: Vec<bool> },
    WriteRegisters { start: u16, values: Vec<u16> },
    ReadFile(Vec<FileRecordRef>),
    WriteFile(Vec<FileWriteModel>),
    MaskWrite(MaskWrite),
    ReadWrite { read_start: u16, read_quantity: u16, write_start: u16, values: Vec<u16> },
    ReadFifo(ReadFifo),
    ReadDeviceId(ReadDeviceIdCode, u8),
    RawMei(MeiType, Vec<u8>),
    Custom(u8, Vec<u8>),
}

impl Model for RequestModel {
    fn with<R>(&self, f: impl FnOnce(Pdu<'_>) -> R) -> R {
        let writes;
        let request = match self {
            RequestModel::ReadBits { function, start, quantity } => {
                let read = ReadBits::new(*start, *quantity).unwrap();
                match function {
                    FunctionCode::ReadCoils => Request::ReadCoils(read),
                    _ => Request::ReadDiscreteInputs(read),
                }
            }
            RequestModel::ReadRegisters { function, start, quantity } => {
                let read = ReadRegisters::new(*start, *quantity).unwrap();
                match function {
                    FunctionCode::ReadHoldingRegisters => Request::ReadHoldingRegisters(read),
                    _ => Request::ReadInputRegisters(read),
                }
            }
            RequestModel::WriteCoil(c) => Request::WriteSingleCoil(*c),
            RequestModel::WriteRegister(w) => Request::WriteSingleRegister(*w),
            RequestModel::NoData(function) => match function {
                FunctionCode::ReadExceptionStatus => Request::ReadExceptionStatus(NoData),
                FunctionCode::GetCommEventCounter => Request::GetCommEventCounter(NoData),
                FunctionCode::GetCommEventLog => Request::GetCommEventLog(NoData),
                _ => Request::ReportServerId(NoData),
            },
            RequestModel::Diagnostic(d) => Request::Diagnostics(d.build()),
            RequestModel::WriteCoils { start, values } => {
                Request::WriteMultipleCoils(WriteCoils::new(*start, Bits::from_values(values)).unwrap())
            }
            RequestModel::WriteRegisters { start, values } => {
                Request::WriteMultipleRegisters(WriteRegisters::new(*start, Registers::from_values(values)).unwrap())
            }
            RequestModel::ReadFile(refs) => Request::ReadFileRecord(FileRecordReads::new(refs).unwrap()),
            RequestModel::WriteFile(subs) => {
                writes = file_writes(subs);
                Request::WriteFileRecord(FileRecordWrites::new(&writes).unwrap())
            }
            RequestModel::MaskWrite(m) => Request::MaskWriteRegister(*m),
            RequestModel::ReadWrite { read_start, read_quantity, write_start, values } => {
                let values = Registers::from_values(values);
                let rw = ReadWriteRegisters::new(*read_start, *read_quantity, *write_start, values).unwrap();
                Request::ReadWriteMultipleRegisters(rw)
            }
            RequestModel::ReadFifo(r) => Request::ReadFifoQueue(*r),
            RequestModel::ReadDeviceId(code, object_id) => {
                Request::EncapsulatedInterface(MeiRequest::ReadDeviceId(ReadDeviceId::new(*code, *object_id).unwrap()))
            }
            RequestModel::RawMei(mei_type, data) => {
                Request::EncapsulatedInterface(MeiRequest::Other(RawMei::new(*mei_type, data).unwrap()))
            }
            RequestModel::Custom(function, data) => Request::Custom(Custom::new(*function, data).unwrap()),
        };
        f(Pdu::Request(request))
    }
}

#[derive(Clone, Debug)]
enum ResponseModel {
    Bits {
        function: FunctionCode,
        values: Vec<bool>,
    },
    Registers {
        function: FunctionCode,
        values: Vec<u16>,
    },
    WriteCoil(WriteCoil),
    WriteRegister(WriteRegister),
    ExceptionStatus(ExceptionStatus),
    Diagnostic(DiagModel),
    CommEventCounter(CommEventCounter),
    CommEventLog {
        status: u16,
        event_count: u16,
        message_count: u16,
        events: Vec<u8>,
    },
    Written {
        function: FunctionCode,
        start: u16,
        quantity: u16,
    },
    ServerId(Vec<u8>),
    ReadFile(Vec<Vec<u16>>),
    WriteFile(Vec<FileWriteModel>),
    MaskWrite(MaskWrite),
    Fifo(Vec<u16>),
    DeviceId {
        code: ReadDeviceIdCode,
        conformity: u8,
        more_follows: bool,
        next_object_id: u8,
        objects: Vec<(u8, Vec<u8>)>,
    },
    RawMei(MeiType, Vec<u8>),
    Custom(u8, Vec<u8>),
    Exception(ExceptionResponse),
}

impl Model for ResponseModel {
    fn with<R>(&self, f: impl FnOnce(Pdu<'_>) -> R) -> R {
        let records: Vec<Registers<'_>>;
        let writes;
        let objects: Vec<DeviceObject<'_>>;
        let response = match self {
            ResponseModel::Bits { function, values } => {
                let bits = BitValues::new(Bits::from_values(values)).unwrap();
                match function {
                    FunctionCode::ReadCoils => Response::ReadCoils(bits),
                    _ => Response::ReadDiscreteInputs(bits),
                }
            }
            ResponseModel::Registers { function, values } => {
                let regs = RegisterValues::new(Registers::from_values(values)).unwrap();
                match function {
                    FunctionCode::ReadHoldingRegisters => Response::ReadHoldingRegisters(regs),
                    FunctionCode::ReadInputRegisters => Response::ReadInputRegisters(regs),
                    _ => Response::ReadWriteMultipleRegisters(regs),
                }
            }
            ResponseModel::WriteCoil(c) => Response::WriteSingleCoil(*c),
            ResponseModel::WriteRegister(w) => Response::WriteSingleRegister(*w),
            ResponseModel::ExceptionStatus(s) => Response::ReadExceptionStatus(*s),
            ResponseModel::Diagnostic(d) => Response::Diagnostics(d.build()),
            ResponseModel::CommEventCounter(c) => Response::GetCommEventCounter(*c),
            ResponseModel::CommEventLog { status, event_count, message_count, events } => {
                Response::GetCommEventLog(CommEventLog::new(*status, *event_count, *message_count, events).unwrap())
            }
            ResponseModel::Written { function, start, quantity } => match function {
                FunctionCode::WriteMultipleCoils => {
                    Response::WriteMultipleCoils(WrittenCoils::new(*start, *quantity).unwrap())
                }
                _ => Response::WriteMultipleRegisters(WrittenRegisters::new(*start, *quantity).unwrap()),
            },
            ResponseModel::ServerId(data) => Response::ReportServerId(ServerId::new(data).unwrap()),
            ResponseModel::ReadFile(lists) => {
                records = lists.iter().map(|l| Registers::from_values(l)).collect();
                Response::ReadFileRecord(FileSubResponses::new(&records).unwrap())
            }
            ResponseModel::WriteFile(subs) => {
                writes = file_writes(subs);
                Response::WriteFileRecord(FileRecordWrites::new(&writes).unwrap())
            }
            ResponseModel::MaskWrite(m) => Response::MaskWriteRegister(*m),
            ResponseModel::Fifo(values) => {
                Response::ReadFifoQueue(FifoValues::new(Registers::from_values(values)).unwrap())
            }
            ResponseModel::DeviceId { code, conformity, more_follows, next_object_id, objects: list } => {
                objects = list.iter().map(|(id, value)| DeviceObject { id: *id, value }).collect();
                let objects = DeviceObjects::new(&objects).unwrap();
                let id =
                    DeviceIdentification::new(*code, *conformity, *more_follows, *next_object_id, objects).unwrap();
                Response::EncapsulatedInterface(MeiResponse::ReadDeviceId(id))
            }
            ResponseModel::RawMei(mei_type, data) => {
                Response::EncapsulatedInterface(MeiResponse::Other(RawMei::new(*mei_type, data).unwrap()))
            }
            ResponseModel::Custom(function, data) => Response::Custom(Custom::new(*function, data).unwrap()),
            ResponseModel::Exception(e) => Response::Exception(*e),
        };
        f(Pdu::Response(response))
    }
}

/// Any request or response.
#[derive(Clone, Debug)]
enum AnyModel {
    Request(RequestModel),
    Response(ResponseModel),
}

impl Model for AnyModel {
    fn with<R>(&self, f: impl FnOnce(Pdu<'_>) -> R) -> R {
        match self {
            AnyModel::Request(m) => m.with(f),
            AnyModel::Response(m) => m.with(f),
        }
    }
}

// ── Strategies ──────────────────────────────────────────────────────────────────────────────

/// A length in `min..=max`, the ends drawn more often than their share.
fn len_in(min: usize, max: usize) -> impl Strategy<Value = usize> {
    prop_oneof![Just(min), Just(max), min..=max]
}

fn bytes(min: usize, max: usize) -> impl Strategy<Value = Vec<u8>> {
    len_in(min, max).prop_flat_map(|n| vec_of(any::<u8>(), n))
}

fn words(min: usize, max: usize) -> impl Strategy<Value = Vec<u16>> {
    len_in(min, max).prop_flat_map(|n| vec_of(any::<u16>(), n))
}

fn bools(min: usize, max: usize) -> impl Strategy<Value = Vec<bool>> {
    len_in(min, max).prop_flat_map(|n| vec_of(any::<bool>(), n))
}

/// A start address from which `quantity` items stay within 0x0000–0xFFFF.
fn start_for(quantity: usize) -> impl Strategy<Value = u16> {
    let last = word(0x1_0000 - quantity);
    prop_oneof![Just(0), Just(last), 0..=last]
}

/// A start and a quantity in `1..=max` that fit the address space.
fn range(max: u16) -> impl Strategy<Value = (u16, u16)> {
    len_in(1, usize::from(max)).prop_flat_map(|q| (start_for(q), Just(word(q))))
}

/// The longest prefix of `items` whose cost stays within `budget`.
fn fit<T>(items: Vec<T>, budget: usize, cost: impl Fn(&T) -> usize) -> Vec<T> {
    let mut total = 0;
    items
        .into_iter()
        .take_while(|item| {
            total += cost(item);
            total <= budget
        })
        .collect()
}

/// A code from the non-public part of 0x01–0x7F.
fn custom_code() -> impl Strategy<Value = u8> {
    (1u8..=0x7F).prop_filter("a public code", |&c| !FunctionCode::from_u8(c).is_public())
}

fn diagnostic() -> impl Strategy<Value = DiagModel> {
    let named: Vec<DiagnosticCode> =
        DiagnosticCode::ALL.iter().copied().filter(|&c| c != DiagnosticCode::ReturnQueryData).collect();
    let unnamed = any::<u16>().prop_filter("a named sub-function", |&s| DiagnosticCode::from_u16(s).name().is_none());
    prop_oneof![
        bytes(0, Diagnostic::MAX_DATA).prop_map(|d| DiagModel::Data(DiagnosticCode::ReturnQueryData, d)),
        any::<u16>().prop_map(|w| DiagModel::Word(DiagnosticCode::ReturnQueryData, w)),
        (select(named), any::<u16>()).prop_map(|(code, w)| DiagModel::Word(code, w)),
        (unnamed, bytes(0, Diagnostic::MAX_DATA)).prop_map(|(s, d)| DiagModel::Data(DiagnosticCode::from_u16(s), d)),
    ]
}

fn file_writes_model() -> impl Strategy<Value = Vec<FileWriteModel>> {
    let sub = (any::<u16>(), any::<u16>(), prop_oneof![words(1, 4), words(1, 122)]);
    vec_of(sub, 1..=12).prop_map(|subs| fit(subs, 251, |(_, _, data)| 7 + 2 * data.len()))
}

fn mei_type_not_0e() -> impl Strategy<Value = MeiType> {
    any::<u8>().prop_filter("MEI type 0x0E", |&m| m != 0x0E).prop_map(MeiType::from_u8)
}

fn read_device_id_code() -> impl Strategy<Value = ReadDeviceIdCode> {
    select(vec![
        ReadDeviceIdCode::Basic,
        ReadDeviceIdCode::Regular,
        ReadDeviceIdCode::Extended,
        ReadDeviceIdCode::Specific,
    ])
}

fn read_bits_request(function: FunctionCode) -> impl Strategy<Value = RequestModel> {
    range(ReadBits::MAX).prop_map(move |(start, quantity)| RequestModel::ReadBits { function, start, quantity })
}

fn read_registers_request(function: FunctionCode) -> impl Strategy<Value = RequestModel> {
    range(ReadRegisters::MAX).prop_map(move |(start, quantity)| RequestModel::ReadRegisters {
        function,
        start,
        quantity,
    })
}

fn write_coil() -> impl Strategy<Value = WriteCoil> {
    (any::<u16>(), any::<bool>()).prop_map(|(address, value)| WriteCoil { address, value })
}

fn write_register() -> impl Strategy<Value = WriteRegister> {
    (any::<u16>(), any::<u16>()).prop_map(|(address, value)| WriteRegister { address, value })
}

fn mask_write() -> impl Strategy<Value = MaskWrite> {
    (any::<u16>(), any::<u16>(), any::<u16>()).prop_map(|(address, and_mask, or_mask)| MaskWrite {
        address,
        and_mask,
        or_mask,
    })
}

fn no_data_request() -> impl Strategy<Value = RequestModel> {
    let codes = vec![
        FunctionCode::ReadExceptionStatus,
        FunctionCode::GetCommEventCounter,
        FunctionCode::GetCommEventLog,
        FunctionCode::ReportServerId,
    ];
    select(codes).prop_map(RequestModel::NoData)
}

fn write_coils_request() -> impl Strategy<Value = RequestModel> {
    bools(1, usize::from(WriteCoils::MAX))
        .prop_flat_map(|values| (start_for(values.len()), Just(values)))
        .prop_map(|(start, values)| RequestModel::WriteCoils { start, values })
}

fn write_registers_request() -> impl Strategy<Value = RequestModel> {
    words(1, usize::from(WriteRegisters::MAX))
        .prop_flat_map(|values| (start_for(values.len()), Just(values)))
        .prop_map(|(start, values)| RequestModel::WriteRegisters { start, values })
}

fn read_file_request() -> impl Strategy<Value = RequestModel> {
    let sub = (any::<u16>(), any::<u16>(), prop_oneof![1..=4u16, 1..=121u16]);
    vec_of(sub, 1..=35).prop_map(|subs| fit(subs, 245, |&(_, _, length)| 2 + 2 * usize::from(length))).prop_map(
        |subs| {
            RequestModel::ReadFile(
                subs.into_iter().map(|(file, record, length)| FileRecordRef { file, record, length }).collect(),
            )
        },
    )
}

fn read_write_request() -> impl Strategy<Value = RequestModel> {
    (range(ReadRegisters::MAX), words(1, usize::from(ReadWriteRegisters::MAX_WRITE)))
        .prop_flat_map(|(read, values)| (Just(read), start_for(values.len()), Just(values)))
        .prop_map(|((read_start, read_quantity), write_start, values)| RequestModel::ReadWrite {
            read_start,
            read_quantity,
            write_start,
            values,
        })
}

/// Bit responses as parse returns them: whole bytes of bits.
fn bits_response(function: FunctionCode) -> impl Strategy<Value = ResponseModel> {
    len_in(1, 250)
        .prop_flat_map(|n| vec_of(any::<bool>(), 8 * n))
        .prop_map(move |values| ResponseModel::Bits { function, values })
}

fn registers_response() -> impl Strategy<Value = ResponseModel> {
    let functions = vec![
        FunctionCode::ReadHoldingRegisters,
        FunctionCode::ReadInputRegisters,
        FunctionCode::ReadWriteMultipleRegisters,
    ];
    (select(functions), words(1, usize::from(ReadRegisters::MAX)))
        .prop_map(|(function, values)| ResponseModel::Registers { function, values })
}

fn written_response() -> impl Strategy<Value = ResponseModel> {
    let written = |function, max| {
        range(max).prop_map(move |(start, quantity)| ResponseModel::Written { function, start, quantity })
    };
    prop_oneof![
        written(FunctionCode::WriteMultipleCoils, WriteCoils::MAX),
        written(FunctionCode::WriteMultipleRegisters, WriteRegisters::MAX)
    ]
}

fn read_file_response() -> impl Strategy<Value = ResponseModel> {
    vec_of(prop_oneof![words(1, 4), words(1, 121)], 1..=30)
        .prop_map(|lists| ResponseModel::ReadFile(fit(lists, 245, |l| 2 + 2 * l.len())))
}

fn device_id_response() -> impl Strategy<Value = ResponseModel> {
    let objects = prop_oneof![vec_of((any::<u8>(), bytes(0, 20)), 0..=40), vec_of((any::<u8>(), bytes(0, 244)), 1..=2)]
        .prop_map(|objects| fit(objects, DeviceIdentification::MAX_OBJECT_BYTES, |(_, value)| 2 + value.len()));
    (read_device_id_code(), any::<u8>(), any::<bool>(), any::<u8>(), objects).prop_map(
        |(code, conformity, more_follows, next_object_id, objects)| ResponseModel::DeviceId {
            code,
            conformity,
            more_follows,
            next_object_id,
            objects,
        },
    )
}

fn exception_response() -> impl Strategy<Value = ResponseModel> {
    (1u8..=0x7F, any::<u8>()).prop_map(|(function, code)| {
        ResponseModel::Exception(
            ExceptionResponse::new(FunctionCode::from_u8(function), ExceptionCode::from_u8(code)).unwrap(),
        )
    })
}

fn any_request() -> impl Strategy<Value = RequestModel> {
    prop_oneof![
        read_bits_request(FunctionCode::ReadCoils),
        read_registers_request(FunctionCode::ReadInputRegisters),
        write_coil().prop_map(RequestModel::WriteCoil),
        write_register().prop_map(RequestModel::WriteRegister),
        no_data_request(),
        diagnostic().prop_map(RequestModel::Diagnostic),
        write_coils_request(),
        write_registers_request(),
        read_file_request(),
        file_writes_model().prop_map(RequestModel::WriteFile),
        mask_write().prop_map(RequestModel::MaskWrite),
        read_write_request(),
        any::<u16>().prop_map(|address| RequestModel::ReadFifo(ReadFifo { address })),
        (read_device_id_code(), any::<u8>()).prop_map(|(code, id)| RequestModel::ReadDeviceId(code, id)),
        (mei_type_not_0e(), bytes(0, 251)).prop_map(|(t, d)| RequestModel::RawMei(t, d)),
        (custom_code(), bytes(0, MAX_DATA_LEN)).prop_map(|(c, d)| RequestModel::Custom(c, d)),
    ]
}

fn any_response() -> impl Strategy<Value = ResponseModel> {
    prop_oneof![
        bits_response(FunctionCode::ReadDiscreteInputs),
        registers_response(),
        write_coil().prop_map(ResponseModel::WriteCoil),
        write_register().prop_map(ResponseModel::WriteRegister),
        any::<u8>().prop_map(|status| ResponseModel::ExceptionStatus(ExceptionStatus { status })),
        diagnostic().prop_map(ResponseModel::Diagnostic),
        (any::<u16>(), any::<u16>()).prop_map(|(status, event_count)| ResponseModel::CommEventCounter(
            CommEventCounter { status, event_count }
        )),
        comm_event_log_response(),
        written_response(),
        bytes(1, ServerId::MAX).prop_map(ResponseModel::ServerId),
        read_file_response(),
        file_writes_model().prop_map(ResponseModel::WriteFile),
        mask_write().prop_map(ResponseModel::MaskWrite),
        words(0, FifoValues::MAX).prop_map(ResponseModel::Fifo),
        device_id_response(),
        (mei_type_not_0e(), bytes(0, 251)).prop_map(|(t, d)| ResponseModel::RawMei(t, d)),
        (custom_code(), bytes(0, MAX_DATA_LEN)).prop_map(|(c, d)| ResponseModel::Custom(c, d)),
        exception_response(),
    ]
}

fn comm_event_log_response() -> impl Strategy<Value = ResponseModel> {
    (any::<u16>(), any::<u16>(), any::<u16>(), bytes(0, CommEventLog::MAX_EVENTS)).prop_map(
        |(status, event_count, message_count, events)| ResponseModel::CommEventLog {
            status,
            event_count,
            message_count,
            events,
        },
    )
}

fn any_model() -> impl Strategy<Value = AnyModel> {
    prop_oneof![any_request().prop_map(AnyModel::Request), any_response().prop_map(AnyModel::Response)]
}

// ── Round trips, one property per function code and direction ──────────────────────────────

/// One proptest per strategy, each running `assert_round_trip` (parse, emit, re-emit, every
/// shorter buffer, every prefix, an extra byte, `wire_len`) on the value its model builds.
macro_rules! round_trips {
    ($($name:ident: $strategy:expr;)+) => {
        proptest! {
            $(
                #[test]
                fn $name(model in $strategy) {
                    model.with(assert_round_trip);
                }
            )+
        }
    };
}

round_trips! {
    read_coils_requests_round_trip: read_bits_request(FunctionCode::ReadCoils);
    read_discrete_inputs_requests_round_trip: read_bits_request(FunctionCode::ReadDiscreteInputs);
    read_holding_registers_requests_round_trip: read_registers_request(FunctionCode::ReadHoldingRegisters);
    read_input_registers_requests_round_trip: read_registers_request(FunctionCode::ReadInputRegisters);
    write_single_coil_requests_round_trip: write_coil().prop_map(RequestModel::WriteCoil);
    write_single_register_requests_round_trip: write_register().prop_map(RequestModel::WriteRegister);
    requests_without_data_round_trip: no_data_request();
    diagnostics_requests_round_trip: diagnostic().prop_map(RequestModel::Diagnostic);
    write_multiple_coils_requests_round_trip: write_coils_request();
    write_multiple_registers_requests_round_trip: write_registers_request();
    read_file_record_requests_round_trip: read_file_request();
    write_file_record_requests_round_trip: file_writes_model().prop_map(RequestModel::WriteFile);
    mask_write_register_requests_round_trip: mask_write().prop_map(RequestModel::MaskWrite);
    read_write_multiple_registers_requests_round_trip: read_write_request();
    read_fifo_queue_requests_round_trip: any::<u16>().prop_map(|address| RequestModel::ReadFifo(ReadFifo { address }));
    read_device_id_requests_round_trip:
        (read_device_id_code(), any::<u8>()).prop_map(|(code, id)| RequestModel::ReadDeviceId(code, id));
    raw_mei_requests_round_trip: (mei_type_not_0e(), bytes(0, 251)).prop_map(|(t, d)| RequestModel::RawMei(t, d));
    custom_requests_round_trip: (custom_code(), bytes(0, MAX_DATA_LEN)).prop_map(|(c, d)| RequestModel::Custom(c, d));

    read_coils_responses_round_trip: bits_response(FunctionCode::ReadCoils);
    read_discrete_inputs_responses_round_trip: bits_response(FunctionCode::ReadDiscreteInputs);
    read_register_responses_round_trip: registers_response();
    write_single_coil_responses_round_trip: write_coil().prop_map(ResponseModel::WriteCoil);
    write_single_register_responses_round_trip: write_register().prop_map(ResponseModel::WriteRegister);
    read_exception_status_responses_round_trip:
        any::<u8>().prop_map(|status| ResponseModel::ExceptionStatus(ExceptionStatus { status }));
    diagnostics_responses_round_trip: diagnostic().prop_map(ResponseModel::Diagnostic);
    get_comm_event_counter_responses_round_trip: (any::<u16>(), any::<u16>())
        .prop_map(|(status, event_count)| ResponseModel::CommEventCounter(CommEventCounter { status, event_count }));
    get_comm_event_log_responses_round_trip: comm_event_log_response();
    write_multiple_responses_round_trip: written_response();
    report_server_id_responses_round_trip: bytes(1, ServerId::MAX).prop_map(ResponseModel::ServerId);
    read_file_record_responses_round_trip: read_file_response();
    write_file_record_responses_round_trip: file_writes_model().prop_map(ResponseModel::WriteFile);
    mask_write_register_responses_round_trip: mask_write().prop_map(ResponseModel::MaskWrite);
    read_fifo_queue_responses_round_trip: words(0, FifoValues::MAX).prop_map(ResponseModel::Fifo);
    read_device_id_responses_round_trip: device_id_response();
    raw_mei_responses_round_trip: (mei_type_not_0e(), bytes(0, 251)).prop_map(|(t, d)| ResponseModel::RawMei(t, d));
    custom_responses_round_trip: (custom_code(), bytes(0, MAX_DATA_LEN)).prop_map(|(c, d)| ResponseModel::Custom(c, d));
    exception_responses_round_trip: exception_response();
}

proptest! {
    /// A bit response carries whole bytes: what comes back is the bits sent, padded with
    /// zeros to a multiple of 8 (the exact round trip of such values is in `bugs`).
    #[test]
    fn bit_responses_of_any_count_come_back_padded_with_zeros(values in bools(1, usize::from(ReadBits::MAX))) {
        let sent = Response::ReadCoils(BitValues::new(Bits::from_values(&values)).unwrap());
        let bytes = Pdu::Response(sent).to_bytes();
        let received = body!(Response::parse(&bytes).unwrap(), Response::ReadCoils).values();
        prop_assert_eq!(received.len(), values.len().div_ceil(8) * 8);
        prop_assert_eq!(received.truncated(values.len()), Some(Bits::from_values(&values)));
        prop_assert!(received.iter().skip(values.len()).all(|on| !on));
    }
}

// ── Arbitrary and mutated bytes ─────────────────────────────────────────────────────────────

/// One edit of a valid PDU's bytes.
#[derive(Clone, Debug)]
enum Edit {
    Set(Index, u8),
    Insert(Index, u8),
    Remove(Index),
    Truncate(Index),
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<Index>(), any::<u8>()).prop_map(|(i, b)| Edit::Set(i, b)),
        (any::<Index>(), any::<u8>()).prop_map(|(i, b)| Edit::Insert(i, b)),
        any::<Index>().prop_map(Edit::Remove),
        any::<Index>().prop_map(Edit::Truncate),
    ]
}

fn apply(bytes: &mut Vec<u8>, edit: &Edit) {
    if bytes.is_empty() {
        return;
    }
    match edit {
        Edit::Set(i, b) => {
            let i = i.index(bytes.len());
            bytes[i] = *b;
        }
        Edit::Insert(i, b) => bytes.insert(i.index(bytes.len() + 1), *b),
        Edit::Remove(i) => {
            bytes.remove(i.index(bytes.len()));
        }
        Edit::Truncate(i) => bytes.truncate(i.index(bytes.len())),
    }
}

fn public_code() -> impl Strategy<Value = u8> {
    select(FunctionCode::ALL.iter().map(|c| c.value()).collect::<Vec<u8>>())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1024))]

    #[test]
    fn arbitrary_bytes_never_panic_and_whatever_parses_re_emits_exactly(bytes in vec_of(any::<u8>(), 0..=300)) {
        assert_parse_is_canonical(&bytes);
    }

    #[test]
    fn arbitrary_bodies_after_each_public_or_exception_code_never_panic(
        function in prop_oneof![public_code(), public_code().prop_map(|c| c | 0x80), any::<u8>()],
        body in vec_of(any::<u8>(), 0..=300),
    ) {
        let bytes = [&[function][..], &body].concat();
        assert_parse_is_canonical(&bytes);
    }

    #[test]
    fn mutated_valid_pdus_never_panic_and_whatever_parses_re_emits_exactly(
        model in any_model(),
        edits in vec_of(edit(), 1..=3),
    ) {
        model.with(|pdu| {
            let mut bytes = pdu.to_bytes();
            for e in &edits {
                apply(&mut bytes, e);
            }
            assert_parse_is_canonical(&bytes);
        });
    }

    #[test]
    fn valid_pdus_of_any_kind_round_trip(model in any_model()) {
        model.with(assert_round_trip);
    }
}
