//! Report by exception: whether a cell's latest reading differs enough from the one last
//! published (or stored while offline) to be sent again.
//!
//! A number is sent when it moved *beyond* the cell's deadband, in engineering units: more
//! than `deadband` away from the last published value (0: any change). A bit or a text is sent
//! on any change. A cell whose read failed (an exception reply, a value that does not decode)
//! is sent once as null, and again when it reads a value.

use std::cmp::Ordering;

use ferrobus::poll::Cell;
use ferrobus_profile::Value;

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
    if !numeric || deadband <= 0.0 {
        return true;
    }
    match (cell.scaled(old), cell.scaled(new)) {
        // NaN on either side is a change.
        (Some(a), Some(b)) => matches!((b - a).abs().partial_cmp(&deadband), Some(Ordering::Greater) | None),
        _ => true,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ferrobus::poll::{Format, Order, Table};

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
    fn a_nan_is_a_change() {
        let cell = scaled_cell(1.0);
        let x = |f| Seen::Value(Value::Float(f));
        assert!(beyond(&cell, &x(1.0), &x(f64::NAN), 5.0));
        assert!(beyond(&cell, &x(f64::NAN), &x(1.0), 5.0));
    }
}
