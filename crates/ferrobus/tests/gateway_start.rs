//! `Gateway::start`'s typed errors: a routing mistake is told apart from a port that fails.

use ferrobus::gateway::{Gateway, GatewayConfig, GatewayError, GatewayLine, Route, Routes};
use ferrobus::{ClientConfig, Error, SerialConfig, Transport};
use ferrobus_proto::frame::LineConfig;

fn line(path: &str) -> GatewayLine {
    let serial = SerialConfig::new(path, LineConfig::new(9600).unwrap());
    GatewayLine::new(Transport::rtu(serial).with_reopen(false), ClientConfig::default())
}

fn config(lines: Vec<GatewayLine>, routes: Routes) -> GatewayConfig {
    GatewayConfig { lines, routes, broadcast_ack: false, cache_max_age: None }
}

#[tokio::test]
async fn a_unit_routed_to_a_line_that_does_not_exist_is_a_routing_error_before_any_port_is_opened() {
    let mut routes = Routes::all_on(0);
    routes.set(7, Route { line: 2, unit: 7 });
    // The port does not exist either: the routes are checked first.
    let Err(error) =
        Gateway::start(config(vec![line("/nonexistent/ferrobus-a"), line("/nonexistent/ferrobus-b")], routes)).await
    else {
        panic!("started");
    };
    assert!(matches!(error, GatewayError::Routing { unit: 7, line: 2, lines: 2 }), "{error:?}");
    assert_eq!(error.to_string(), "unit 7 is routed to line 2, but there are 2 lines (numbered from 0)");
}

#[tokio::test]
async fn a_port_that_cannot_be_opened_is_an_io_error_naming_its_line_and_port() {
    let mut routes = Routes::new();
    routes.set(1, Route { line: 0, unit: 1 });
    let Err(error) = Gateway::start(config(vec![line("/nonexistent/ferrobus-gw")], routes)).await else {
        panic!("started");
    };
    let GatewayError::Io { line: 0, source } = &error else { panic!("{error:?}") };
    assert!(matches!(source, Error::Io { .. }), "{source:?}");
    assert!(error.to_string().contains("/nonexistent/ferrobus-gw"), "{error}");
}
