//! What to watch: raw read definitions (`[UNIT:]TABLE:ADDRESS[:COUNT][@RATE]`), profile points
//! (a code, a glob or `group:NAME`, with `@RATE`), and the session file that saves them with
//! the cells' formats, aliases and trends.

use std::time::Duration;

use ferrobus_profile::Order;
use ferrobus_profile::{Point, Profile, Table};
use ferrobus_tools::poll::Group;
use ferrobus_tools::poll::session::{CellDef, PointsDef, ReadDef, Session, order_of, period, table_from_name};

use super::model::{Cell, Definition, Format};
use crate::address::RangeWord;
use crate::exit::CliError;

/// The rate of a definition that gives none.
pub(crate) const DEFAULT_EVERY: Duration = Duration::from_secs(1);

/// A number by the one number grammar ([`ferrobus::text::number`]: decimal or 0x hex).
fn number(text: &str, what: &str, spec: &str) -> Result<u32, CliError> {
    ferrobus::text::number(text, u64::from(u32::MAX))
        .map(|n| u32::try_from(n).unwrap_or(u32::MAX))
        .map_err(|e| CliError::Usage(format!("'{}': {what}: {e}", ferrobus::log::escape(spec))))
}

/// Splits `@RATE` off a definition.
fn rate(spec: &str) -> Result<(&str, Duration), CliError> {
    let Some((body, rate)) = spec.rsplit_once('@') else { return Ok((spec, DEFAULT_EVERY)) };
    let every = ferrobus_sim::fault::parse_duration(rate).map_err(|e| CliError::Usage(format!("'{spec}': {e}")))?;
    if every < Duration::from_millis(10) {
        return Err(CliError::Usage(format!("'{spec}': a rate under 10 ms is not a rate a screen can show")));
    }
    Ok((body, every))
}

/// Parses one definition: raw, its address a wire address, or (with a profile) points by
/// name, glob or `group:NAME`.
pub(crate) fn parse(spec: &str, default_unit: u8, profile: Option<&Profile>) -> Result<Vec<Definition>, CliError> {
    let wire = |address: &str, _: crate::address::Table| -> Result<u16, CliError> {
        number(address, "the address", spec).and_then(|a| {
            u16::try_from(a).map_err(|_| CliError::Usage(format!("'{spec}': address {a} is past 0xFFFF")))
        })
    };
    parse_numbered(spec, default_unit, profile, &wire)
}

/// [`parse`], a raw definition's address numbered by `address` (the command line's rule,
/// [`crate::connect::ConnectArgs::address`]). The raw range is the one word
/// `[UNIT:]TABLE:ADDRESS[:COUNT]` that `poll` takes too ([`RangeWord`]).
pub(crate) fn parse_numbered(
    spec: &str,
    default_unit: u8,
    profile: Option<&Profile>,
    address: &dyn Fn(&str, crate::address::Table) -> Result<u16, CliError>,
) -> Result<Vec<Definition>, CliError> {
    let (body, every) = rate(spec)?;
    if let Some(range) = RangeWord::parse(body) {
        let range = range?;
        let (table, count) = (range.table, range.count.unwrap_or(1));
        let max = table.max_read();
        if usize::from(count) > max {
            return Err(CliError::Usage(format!("'{spec}': the count is 1 to {max} for {table}")));
        }
        let start = address(range.address, table)?;
        if u32::from(start) + u32::from(count) > 0x1_0000 {
            return Err(CliError::Usage(format!("'{spec}': the range passes the last address 0xFFFF")));
        }
        let unit = range.unit.unwrap_or(default_unit);
        return Ok(vec![Definition::raw(unit, table.into(), start, count, every)]);
    }
    let parts: Vec<&str> = body.split(':').collect();
    let (unit, rest) = (default_unit, parts.as_slice());
    let Some(profile) = profile else {
        return Err(CliError::Usage(format!(
            "'{spec}' is not a read definition ([UNIT:]TABLE:ADDRESS[:COUNT][@RATE], TABLE = coils, discrete, \
             holding or input); point names need --device"
        )));
    };
    let name = rest.join(":");
    let points: Vec<&Point> = match name.strip_prefix("group:") {
        Some(group) => profile.group(group),
        None => profile.find(&name),
    };
    let points: Vec<&Point> = points.into_iter().filter(|p| p.readable()).collect();
    if points.is_empty() {
        return Err(CliError::Usage(format!(
            "'{spec}': no readable point of {} is called that (see `ferrobus profile show`)",
            profile.device.name
        )));
    }
    points_to_panes(spec, profile, unit, every, &points)
}

/// The points as panes: one per table, filled by the profile planner's reads
/// ([`Group::points`]: the fewest within the device's limits, never across an unmapped hole
/// outside a span, never splitting a value), the points as cells.
fn points_to_panes(
    spec: &str,
    profile: &Profile,
    unit: u8,
    every: Duration,
    points: &[&Point],
) -> Result<Vec<Definition>, CliError> {
    let codes: Vec<String> = points.iter().map(|p| p.code.clone()).collect();
    let groups =
        Group::points(profile, unit, &codes, &[], every).map_err(|e| CliError::Usage(format!("'{spec}': {e}")))?;
    let mut panes = Vec::new();
    for table in [Table::Holding, Table::Input, Table::Coils, Table::DiscreteInputs] {
        let these: Vec<&Group> = groups.iter().filter(|g| g.table == table).collect();
        let (Some(first), Some(end)) =
            (these.iter().map(|g| g.start).min(), these.iter().map(|g| u32::from(g.start) + u32::from(g.count)).max())
        else {
            continue;
        };
        let cells = these
            .iter()
            .flat_map(|g| &g.cells)
            .map(|c| Cell {
                point: c.point.clone(),
                format: Format::Named,
                alias: if c.point.label.is_empty() { c.point.code.clone() } else { c.point.label.clone() },
                trended: false,
            })
            .collect();
        let count = u16::try_from(end - u32::from(first)).unwrap_or(u16::MAX);
        let mut pane = Definition::with_cells(unit, table, first, count, every, cells);
        pane.reads = these.iter().map(|g| (g.start, g.count)).collect();
        panes.push(pane);
    }
    Ok(panes)
}

/// The session file of the panes: the one `ferrobus poll --session` takes
/// ([`ferrobus_tools::poll::Session`]). Raw panes are `[[read]]`s with their cells' formats, orders,
/// aliases and trends (the read's order is its first multi-register cell's; a cell in another
/// order names its own); panes of profile points are `[[points]]` of `device` with the codes
/// of the trended points.
pub(crate) fn session_of(device: Option<&str>, panes: &[Definition]) -> Session {
    let mut session = Session::default();
    for pane in panes {
        let every = Some(format!("{}ms", pane.every.as_millis()));
        if pane.cells.iter().any(|c| c.format == Format::Named) {
            session.points.push(PointsDef {
                unit: pane.unit,
                device: device.unwrap_or_default().to_string(),
                names: pane.cells.iter().map(|c| c.point.code.clone()).collect(),
                groups: Vec::new(),
                every,
                trends: pane.cells.iter().filter(|c| c.trended).map(|c| c.point.code.clone()).collect(),
            });
            continue;
        }
        let read_order = pane.cells.iter().find_map(|c| c.format.order()).unwrap_or_default();
        let own_order = |c: &Cell| c.format.order().filter(|o| *o != read_order);
        let cells = pane
            .cells
            .iter()
            .filter(|c| c.format != Format::U16 || !c.alias.is_empty() || c.trended)
            .map(|c| CellDef {
                address: c.point.address,
                alias: (!c.alias.is_empty()).then(|| c.alias.clone()),
                format: (c.format != Format::U16 && !pane.is_bits()).then(|| poll_format(c.format).to_string()),
                order: own_order(c).map(|o| o.name().to_string()),
                trend: c.trended,
            })
            .collect();
        session.reads.push(ReadDef {
            name: None,
            unit: pane.unit,
            table: pane.table_name().to_string(),
            address: pane.address,
            count: pane.count,
            format: None,
            order: (read_order != Order::Abcd).then(|| read_order.name().to_string()),
            every,
            cells,
        });
    }
    session
}

/// The poll library's name of a format.
fn poll_format(format: Format) -> &'static str {
    match format {
        Format::Named | Format::U16 => "u16",
        Format::I16 => "i16",
        Format::Hex => "hex",
        Format::Binary => "binary",
        Format::U32(_) => "u32",
        Format::I32(_) => "i32",
        Format::F32(_) => "f32",
        Format::F64(_) => "f64",
    }
}

/// The panes of a session file; `origin` names it in errors.
pub(crate) fn panes_of(session: &Session, origin: &str) -> Result<Vec<Definition>, CliError> {
    let bad = |what: String, problem: String| CliError::Usage(format!("{origin}: {what}: {problem}"));
    let mut panes = Vec::new();
    for (i, read) in session.reads.iter().enumerate() {
        let what = || format!("read {}", i + 1);
        table_from_name(&read.table).map_err(|e| bad(what(), e.to_string()))?;
        let every = period(read.every.as_deref()).map_err(|e| bad(what(), e.to_string()))?;
        let order = order_of(read.order.as_deref()).map_err(|e| bad(what(), e.to_string()))?.unwrap_or_default();
        let spec = format!("{}:{}:{}:{}", read.unit, read.table, read.address, read.count);
        let mut pane = parse(&spec, read.unit, None).map_err(|e| bad(what(), format!("{e:?}")))?.remove(0);
        pane.every = every;
        let format_of = |name: &str| Format::parse(name).map(|f| f.with_order(order)).map_err(|e| bad(what(), e));
        if let Some(format) = &read.format {
            let format = format_of(format)?;
            pane.cells.iter_mut().for_each(|c| c.set_format(format));
        }
        for def in &read.cells {
            let cell = pane
                .cells
                .iter_mut()
                .find(|c| c.point.address == def.address)
                .ok_or_else(|| bad(what(), format!("cell {:#06x} is not in the range read", def.address)))?;
            if let Some(format) = &def.format {
                cell.set_format(format_of(format)?);
            }
            if let Some(own) = order_of(def.order.as_deref()).map_err(|e| bad(what(), e.to_string()))? {
                cell.set_format(cell.format.with_order(own));
            }
            if let Some(alias) = &def.alias {
                cell.alias.clone_from(alias);
            }
            cell.trended = def.trend;
        }
        panes.push(pane);
    }
    for (i, def) in session.points.iter().enumerate() {
        let what = || format!("points {}", i + 1);
        let every = period(def.every.as_deref()).map_err(|e| bad(what(), e.to_string()))?;
        let profile = Profile::load(&def.device).map_err(|e| bad(what(), e.to_string()))?;
        let mut points: Vec<&Point> = Vec::new();
        for name in &def.names {
            points.extend(profile.find(name));
        }
        for group in &def.groups {
            points.extend(profile.group(group));
        }
        points.retain(|p| p.readable());
        points.sort_by_key(|p| (p.address, p.code.clone()));
        points.dedup_by(|a, b| a.code == b.code);
        if points.is_empty() {
            return Err(bad(what(), "no readable point of the profile has those names or groups".into()));
        }
        let mut these = points_to_panes(&what(), &profile, def.unit, every, &points)?;
        for cell in these.iter_mut().flat_map(|p| p.cells.iter_mut()) {
            cell.trended = def.trends.iter().any(|t| t.eq_ignore_ascii_case(&cell.point.code));
        }
        let shown =
            |code: &String| these.iter().flat_map(|p| &p.cells).any(|c| c.point.code.eq_ignore_ascii_case(code));
        if let Some(code) = def.trends.iter().find(|t| !shown(t)) {
            return Err(bad(what(), format!("trend {code:?} is not one of the points watched")));
        }
        panes.extend(these);
    }
    Ok(panes)
}
