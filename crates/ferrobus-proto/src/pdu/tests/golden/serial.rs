//! Goldens of the serial-line management codes: 0x07, 0x08, 0x0B, 0x0C, 0x11 (spec §6.7–6.10,
//! §6.13). The 0x08 counters 0x0A–0x12 and 0x14 are table-driven in `golden.rs`.

use super::*;

goldens! {
    // ── 0x07 Read Exception Status ───────────────────────────────────────────────────────────

    /// No data.
    read_exception_status_request: Request [
        0x07, // function code: 0x07 Read Exception Status
    ] => Request::ReadExceptionStatus(NoData),
    |r| {
        assert_eq!(*body!(r, Request::ReadExceptionStatus), NoData);
    }

    /// The spec's example (§6.7): outputs 0110_1101.
    read_exception_status_response: Response [
        0x07, // function code: 0x07 Read Exception Status
        0x6D, // status outputs 8…1: 0110_1101
    ] => Response::ReadExceptionStatus(ExceptionStatus { status: 0x6D }),
    |r| {
        assert_eq!(body!(r, Response::ReadExceptionStatus).status, 0x6D);
    }

    // ── 0x08 Diagnostics (0x0A–0x12 and 0x14 are table-driven in golden.rs) ──────────────────

    /// RKC COM-ML p.143, slave 1: loopback of 0x1F34 (`01 08 00 00 1F 34 E9 EC`).
    diagnostics_return_query_data_request: Request [
        0x08,       // function code: 0x08 Diagnostics
        0x00, 0x00, // sub-function: 0x0000 Return Query Data
        0x1F, 0x34, // data: any, echoed
    ] => Request::Diagnostics(Diagnostic::with_data(DiagnosticCode::ReturnQueryData, &[0x1F, 0x34]).unwrap()),
    |r| {
        let d = body!(r, Request::Diagnostics);
        assert_eq!(d.sub_function(), DiagnosticCode::ReturnQueryData);
        assert_eq!((d.data(), d.word()), (&[0x1F, 0x34][..], Some(0x1F34)));
    }

    /// RKC COM-ML p.143: the response is identical to the request.
    diagnostics_return_query_data_response: Response [
        0x08,       // function code: 0x08 Diagnostics
        0x00, 0x00, // sub-function: 0x0000 Return Query Data
        0x1F, 0x34, // data: echoed
    ] => Response::Diagnostics(Diagnostic::with_word(DiagnosticCode::ReturnQueryData, 0x1F34)),
    |r| {
        let d = body!(r, Response::Diagnostics);
        assert_eq!((d.sub_function(), d.data()), (DiagnosticCode::ReturnQueryData, &[0x1F, 0x34][..]));
    }

    /// Return Query Data echoes any data, an odd number of bytes too.
    diagnostics_return_query_data_with_odd_data_request: Request [
        0x08,             // function code: 0x08 Diagnostics
        0x00, 0x00,       // sub-function: 0x0000 Return Query Data
        0xA5, 0x37, 0x01, // data: three bytes
    ] => Request::Diagnostics(Diagnostic::with_data(DiagnosticCode::ReturnQueryData, &[0xA5, 0x37, 0x01]).unwrap()),
    |r| {
        let d = body!(r, Request::Diagnostics);
        assert_eq!((d.data(), d.word()), (&[0xA5, 0x37, 0x01][..], None));
    }

    /// Restart communications and clear the event log too.
    diagnostics_restart_communications_request: Request [
        0x08,       // function code: 0x08 Diagnostics
        0x00, 0x01, // sub-function: 0x0001 Restart Communications Option
        0xFF, 0x00, // data: 0xFF00, also clear the comm event log
    ] => Request::Diagnostics(Diagnostic::with_word(DiagnosticCode::RestartCommunications, 0xFF00)),
    |r| {
        let d = body!(r, Request::Diagnostics);
        assert_eq!((d.sub_function(), d.word()), (DiagnosticCode::RestartCommunications, Some(0xFF00)));
    }

    /// The echo, sent before the restart.
    diagnostics_restart_communications_response: Response [
        0x08,       // function code: 0x08 Diagnostics
        0x00, 0x01, // sub-function: 0x0001 Restart Communications Option
        0xFF, 0x00, // data: echoed
    ] => Response::Diagnostics(Diagnostic::with_word(DiagnosticCode::RestartCommunications, 0xFF00)),
    |r| {
        let d = body!(r, Response::Diagnostics);
        assert_eq!((d.sub_function(), d.word()), (DiagnosticCode::RestartCommunications, Some(0xFF00)));
    }

    /// Force listen-only mode; the server sends no response at all.
    diagnostics_force_listen_only_request: Request [
        0x08,       // function code: 0x08 Diagnostics
        0x00, 0x04, // sub-function: 0x0004 Force Listen Only Mode
        0x00, 0x00, // data: 0x0000
    ] => Request::Diagnostics(Diagnostic::with_word(DiagnosticCode::ForceListenOnly, 0)),
    |r| {
        let d = body!(r, Request::Diagnostics);
        assert_eq!((d.sub_function(), d.word()), (DiagnosticCode::ForceListenOnly, Some(0)));
    }

    // ── 0x0B Get Comm Event Counter ──────────────────────────────────────────────────────────

    /// No data.
    get_comm_event_counter_request: Request [
        0x0B, // function code: 0x0B Get Comm Event Counter
    ] => Request::GetCommEventCounter(NoData),
    |r| {
        assert_eq!(*body!(r, Request::GetCommEventCounter), NoData);
    }

    /// The spec's example (§6.9): busy, 264 events.
    get_comm_event_counter_response: Response [
        0x0B,       // function code: 0x0B Get Comm Event Counter
        0xFF, 0xFF, // status: 0xFFFF, a previous command is still in progress
        0x01, 0x08, // event count: 264
    ] => Response::GetCommEventCounter(CommEventCounter { status: 0xFFFF, event_count: 0x0108 }),
    |r| {
        let c = body!(r, Response::GetCommEventCounter);
        assert_eq!((c.status, c.event_count), (0xFFFF, 264));
    }

    // ── 0x0C Get Comm Event Log ──────────────────────────────────────────────────────────────

    /// No data.
    get_comm_event_log_request: Request [
        0x0C, // function code: 0x0C Get Comm Event Log
    ] => Request::GetCommEventLog(NoData),
    |r| {
        assert_eq!(*body!(r, Request::GetCommEventLog), NoData);
    }

    /// The spec's example (§6.10): two events, most recent first.
    get_comm_event_log_response: Response [
        0x0C,       // function code: 0x0C Get Comm Event Log
        0x08,       // byte count: 6 + 2 events
        0x00, 0x00, // status: 0x0000, ready
        0x01, 0x08, // event count: 264
        0x01, 0x21, // message count: 289
        0x20,       // event 0: the server entered listen-only mode
        0x00,       // event 1: communication restart
    ] => Response::GetCommEventLog(CommEventLog::new(0, 0x0108, 0x0121, &[0x20, 0x00]).unwrap()),
    |r| {
        let log = body!(r, Response::GetCommEventLog);
        assert_eq!((log.status(), log.event_count(), log.message_count()), (0, 264, 289));
        assert_eq!(log.events(), [0x20, 0x00]);
    }

    // ── 0x11 Report Server ID ────────────────────────────────────────────────────────────────

    /// No data.
    report_server_id_request: Request [
        0x11, // function code: 0x11 Report Server ID
    ] => Request::ReportServerId(NoData),
    |r| {
        assert_eq!(*body!(r, Request::ReportServerId), NoData);
    }

    /// A device-specific answer: id, run indicator, additional data, kept whole.
    report_server_id_response: Response [
        0x11,       // function code: 0x11 Report Server ID
        0x04,       // byte count: 4
        0x2A,       // server id (device-specific)
        0xFF,       // run indicator: 0xFF, ON
        b'R', b'X', // additional data: "RX"
    ] => Response::ReportServerId(ServerId::new(&[0x2A, 0xFF, b'R', b'X']).unwrap()),
    |r| {
        assert_eq!(body!(r, Response::ReportServerId).data(), [0x2A, 0xFF, b'R', b'X']);
    }
}
