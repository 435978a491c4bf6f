//! Report by exception: whether a cell's latest reading differs enough from the one last
//! published (or stored while offline) to be sent again.
//!
//! A number is sent when it moved *beyond* the cell's deadband, in engineering units, by the
//! one rule `poll --on-change` follows too ([`ferrobus_profile::beyond_deadband`]): more than
//! `deadband` away from the last published value (0: any change); a NaN after a number and a
//! number after a NaN are sent, a NaN after a NaN is not. A bit or a text is sent on any change. A cell whose read failed (an exception reply, a value that does not decode)
//! is sent once as null, and again when it reads a value.

use ferrobus_profile::{Value, beyond_deadband};
use ferrobus_tools::poll::Cell;

/// What is known of a cell.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Seen {
    /// Never read (its group has not answered yet).
    Unread,
    /// Its raw value.
    Value(Value),
    /// The read failed: the device's exception or why the registers do not decode.
    Failed(String),
}

/// Whether `latest` is to be published after `published`.
pub(crate) fn beyond(cell: &Cell, published: &Seen, latest: &Seen, deadband: f64) -> bool {
    match (published, latest) {
        (_, Seen::Unread) | (Seen::Failed(_), Seen::Failed(_)) => false,
        (Seen::Value(old), Seen::Value(new)) => value_moved(cell, old, new, deadband),
        _ => true,
    }
}

fn value_moved(cell: &Cell, old: &Value, new: &Value, deadband: f64) -> bool {
    if old == new {
        return false;
    }
    let numeric = matches!((old, new), (Value::Int(_) | Value::Float(_), Value::Int(_) | Value::Float(_)));
    if !numeric {
        return true;
    }
    match (cell.scaled(old), cell.scaled(new)) {
        (Some(a), Some(b)) => beyond_deadband(a, b, deadband),
        _ => true,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ferrobus_tools::poll::{Format, Order, Table};

    fn scaled_cell(scale: f64) -> Cell {
        let mut cell = Cell::raw(Table::Holding, 0, Format::U16, Order::default(), Some("f"));
        cell.point.scale = scale;
        cell
    }

    #[test]
    fn a_number_is_sent_only_beyond_the_deadband_in_engineering_units() {
        // Raw 6000 × 0.01 = 60.00 Hz; a deadband of 0.5 Hz.
        let cell = scaled_cell(0.01);
        let at = |n| Seen::Value(Value::Int(n));
        assert!(!beyond(&cell, &at(6000), &at(6050), 0.5), "exactly 0.5 Hz is not beyond 0.5");
        assert!(beyond(&cell, &at(6000), &at(6051), 0.5), "0.51 Hz is");
        assert!(beyond(&cell, &at(6000), &at(5949), 0.5), "downwards too");
        assert!(!beyond(&cell, &at(6000), &at(6000), 0.0));
        assert!(beyond(&cell, &at(6000), &at(6001), 0.0), "a deadband of 0 sends any change");
    }

    #[test]
    fn bits_and_texts_are_sent_on_any_change_whatever_the_deadband() {
        let cell = scaled_cell(1.0);
        let bit = |b| Seen::Value(Value::Bool(b));
        assert!(beyond(&cell, &bit(false), &bit(true), 10.0));
        assert!(!beyond(&cell, &bit(true), &bit(true), 10.0));
        let text = |s: &str| Seen::Value(Value::Text(s.into()));
        assert!(beyond(&cell, &text("a"), &text("b"), 10.0));
    }

    #[test]
    fn a_failed_read_is_sent_once_and_the_first_value_always() {
        let cell = scaled_cell(1.0);
        let failed = Seen::Failed("exception 0x02".into());
        let value = Seen::Value(Value::Int(1));
        assert!(beyond(&cell, &value, &failed, 100.0));
        assert!(!beyond(&cell, &failed, &Seen::Failed("again".into()), 100.0));
        assert!(beyond(&cell, &failed, &value, 100.0));
        assert!(beyond(&cell, &Seen::Unread, &value, 100.0));
        assert!(!beyond(&cell, &value, &Seen::Unread, 0.0));
    }

    #[test]
    fn a_change_between_nan_and_a_number_is_sent_and_nan_after_nan_is_not() {
        let cell = scaled_cell(1.0);
        let x = |f| Seen::Value(Value::Float(f));
        // (last, now, deadband, sent): the table of ferrobus_profile::beyond_deadband, as poll.
        for (last, now, deadband, sent) in [
            (1.0, f64::NAN, 5.0, true),
            (f64::NAN, 1.0, 5.0, true),
            (f64::NAN, f64::NAN, 5.0, false),
            (f64::NAN, f64::NAN, 0.0, false),
            (10.0, 10.5, 0.5, false),
            (10.0, 10.6, 0.5, true),
            (f64::INFINITY, f64::INFINITY, 0.5, false),
        ] {
            assert_eq!(beyond(&cell, &x(last), &x(now), deadband), sent, "{last} -> {now} (deadband {deadband})");
        }
    }
}
