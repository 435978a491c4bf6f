//! A `[[line.device]]`: its profile, the read requests of its points and raw ranges, its
//! metric names (unique) and deadbands.

use std::collections::HashMap;
use std::ops::Range;
use std::time::Duration;

use ferrobus_profile::{Order, Point, Profile, Table};
use ferrobus_tools::poll::{Cell, Format, Group, GroupError, Layout};
use toml::Spanned;

use super::super::DeviceSpec;
use super::super::raw::{self, Text};
use super::{Cx, sparkplug_id};

/// The default poll period of a device.
const DEFAULT_EVERY: Duration = Duration::from_secs(1);
/// Polls without a reply before a device is declared dead, unless `death_after` says.
const DEFAULT_DEATH_AFTER: u32 = 3;

/// One set of profile points polled at one rate: the device's own, or a `[[line.device.poll]]`.
struct PointSet<'a> {
    span: Range<usize>,
    every: Duration,
    points: &'a [Text],
    groups: &'a [Text],
    deadband: f64,
}

/// Where a group came from, to point at the second use of a metric name.
enum Source<'a> {
    Points(&'a PointSet<'a>),
    Raw(&'a Spanned<raw::Raw>),
}

/// A device, with every problem of it reported.
pub(super) fn resolve(cx: &mut Cx<'_>, d: &raw::Device) -> Option<DeviceSpec> {
    let errors = cx.errors.len();
    let id = d.id.get_ref();
    sparkplug_id(cx, "device", &d.id);
    let unit = u8::try_from(*d.unit.get_ref()).ok().filter(|u| (1..=247).contains(u)).unwrap_or_else(|| {
        let seen = d.unit.get_ref();
        cx.at(d.unit.span(), format!("device {id:?}: unit {seen}; a device's unit is 1 to 247 (0 is broadcast)"));
        1
    });
    let profile = d.profile.as_ref().and_then(|p| cx.profile(p));
    let every = d.every.as_ref().map_or(Some(DEFAULT_EVERY), |e| cx.period("every", e)).unwrap_or(DEFAULT_EVERY);
    let deadband = d.deadband.as_ref().map_or(0.0, |b| cx.deadband("deadband", b));
    let death_after = match &d.death_after {
        None => DEFAULT_DEATH_AFTER,
        Some(n) => u32::try_from(*n.get_ref()).ok().filter(|n| *n > 0).unwrap_or_else(|| {
            cx.at(n.span(), format!("death_after = {}: it is 1 or more polls", n.get_ref()));
            DEFAULT_DEATH_AFTER
        }),
    };
    let sets = point_sets(cx, d, every, deadband);
    if d.profile.is_some() && profile.is_none() {
        return None;
    }
    let mut groups: Vec<(Group, f64, Source<'_>)> = Vec::new();
    for set in &sets {
        for group in profile_groups(cx, id, profile.as_deref(), unit, set) {
            groups.push((group, set.deadband, Source::Points(set)));
        }
    }
    for range in &d.raw {
        if let Some(group) = raw_group(cx, id, unit, every, range) {
            let band = range.get_ref().deadband.as_ref().map_or(deadband, |b| cx.deadband("deadband", b));
            groups.push((group, band, Source::Raw(range)));
        }
    }
    if groups.is_empty() && cx.errors.len() == errors {
        cx.at(d.id.span(), format!("device {id:?} polls nothing; give points or groups (with a profile), a [[line.device.poll]] or a [[line.device.raw]]"));
    }
    check_metric_names(cx, id, profile.as_deref(), &groups);
    let deadbands = deadbands(cx, d, &groups);
    (cx.errors.len() == errors).then(|| DeviceSpec {
        id: id.clone(),
        unit,
        profile,
        groups: groups.into_iter().map(|(g, _, _)| g).collect(),
        deadbands,
        death_after,
    })
}

/// The device's own points and groups (if any), then each `[[line.device.poll]]`.
fn point_sets<'a>(cx: &mut Cx<'_>, d: &'a raw::Device, every: Duration, deadband: f64) -> Vec<PointSet<'a>> {
    let mut sets = Vec::new();
    if !d.points.is_empty() || !d.groups.is_empty() {
        let span = d.points.first().or(d.groups.first()).map_or_else(|| d.id.span(), Spanned::span);
        sets.push(PointSet { span, every, points: &d.points, groups: &d.groups, deadband });
    }
    for poll in &d.poll {
        let p = poll.get_ref();
        let every = cx.period("every", &p.every).unwrap_or(every);
        let deadband = p.deadband.as_ref().map_or(deadband, |b| cx.deadband("deadband", b));
        if p.points.is_empty() && p.groups.is_empty() {
            cx.at(poll.span(), "a [[line.device.poll]] names no points and no groups");
        }
        sets.push(PointSet { span: poll.span(), every, points: &p.points, groups: &p.groups, deadband });
    }
    sets
}

/// The planner's groups for one point set; every unknown name is reported, at its place.
fn profile_groups(cx: &mut Cx<'_>, id: &str, profile: Option<&Profile>, unit: u8, set: &PointSet<'_>) -> Vec<Group> {
    let Some(profile) = profile else {
        cx.at(
            set.span.clone(),
            format!("device {id:?} has no profile; points and groups need one (raw ranges do not)"),
        );
        return Vec::new();
    };
    let mut known = true;
    let lookups: [(&[Text], &'static str); 2] = [(set.points, "parameter"), (set.groups, "group")];
    for (names, what) in lookups {
        for name in names {
            let found = if what == "group" { profile.group(name.get_ref()) } else { profile.find(name.get_ref()) };
            if found.is_empty() {
                let error =
                    GroupError::NoSuchPoint { profile: profile.origin.clone(), what, name: name.get_ref().clone() };
                cx.at(name.span(), format!("device {id:?}: {error}{}", suggestion(profile, what)));
                known = false;
            } else if !found.iter().any(|p| p.readable()) {
                let said =
                    format!("{what} {:?} of {} is write-only; it cannot be polled", name.get_ref(), profile.origin);
                cx.at(name.span(), format!("device {id:?}: {said}"));
                known = false;
            }
        }
    }
    if !known {
        return Vec::new();
    }
    let names: Vec<String> = set.points.iter().map(|p| p.get_ref().clone()).collect();
    let groups: Vec<String> = set.groups.iter().map(|g| g.get_ref().clone()).collect();
    Group::points(profile, unit, &names, &groups, set.every).unwrap_or_else(|e| {
        cx.at(set.span.clone(), format!("device {id:?}: {e}"));
        Vec::new()
    })
}

/// What the profile offers, for an unknown name's message.
fn suggestion(profile: &Profile, what: &str) -> String {
    if what == "group" {
        format!(" (its groups: {})", profile.groups().join(", "))
    } else {
        " (a code, a label or a glob such as \"d0*\")".to_string()
    }
}

/// The table names of a raw range.
fn table(name: &str) -> Option<Table> {
    match name.to_ascii_lowercase().as_str() {
        "coils" | "coil" => Some(Table::Coils),
        "discrete" | "discrete_inputs" | "inputs" => Some(Table::DiscreteInputs),
        "holding" | "holding_registers" => Some(Table::Holding),
        "input" | "input_registers" => Some(Table::Input),
        _ => None,
    }
}

/// A `[[line.device.raw]]` range as one group.
fn raw_group(cx: &mut Cx<'_>, id: &str, unit: u8, every: Duration, range: &Spanned<raw::Raw>) -> Option<Group> {
    let errors = cx.errors.len();
    let r = range.get_ref();
    let table = table(r.table.get_ref()).or_else(|| {
        cx.at(r.table.span(), format!("table = {:?}: it is coils, discrete, holding or input", r.table.get_ref()));
        None
    });
    let address = u16::try_from(*r.address.get_ref()).ok().or_else(|| {
        cx.at(
            r.address.span(),
            format!("address = {}: a wire address is 0 to 65535 (0x0000 to 0xFFFF)", r.address.get_ref()),
        );
        None
    });
    let format = r.format.as_ref().map_or(Some(Format::U16), |f| {
        Format::from_name(f.get_ref()).or_else(|| {
            let all: Vec<&str> = Format::ALL.iter().map(|f| f.name()).collect();
            cx.at(f.span(), format!("type = {:?}: it is one of {}", f.get_ref(), all.join(", ")));
            None
        })
    });
    let order = r.order.as_ref().map_or(Some(Order::default()), |o| {
        Order::from_name(o.get_ref()).or_else(|| {
            cx.at(o.span(), format!("order = {:?}: it is ABCD, CDAB, BADC or DCBA", o.get_ref()));
            None
        })
    });
    let every = r.every.as_ref().map_or(Some(every), |e| cx.period("every", e));
    for name in r.names.iter().chain(&r.name) {
        if let Some(problem) = cx.unfit_metric_name(name.get_ref()) {
            cx.at(name.span(), problem);
        }
    }
    if cx.errors.len() > errors {
        return None;
    }
    let (table, address, format, order, every) = (table?, address?, format?, order?, every?);
    let format = if table.is_bits() { Format::Bit } else { format };
    let count = match &r.count {
        None => Some(format.width()),
        Some(c) => u16::try_from(*c.get_ref()).ok().filter(|c| *c > 0).or_else(|| {
            cx.at(c.span(), format!("count = {}: a range reads 1 or more items", c.get_ref()));
            None
        }),
    }?;
    let aliases = raw_names(cx, r, address, count, format)?;
    let layout = Layout { format, order, aliases, ..Layout::default() };
    let name =
        r.name.as_ref().map_or_else(|| format!("u{unit} {}@{address:#06x}", table.name()), |n| n.get_ref().clone());
    let span = ferrobus_tools::poll::RawRange { unit, table, start: address, count, every };
    let group =
        Group::raw(&name, span, &layout).map_err(|e| cx.at(range.span(), format!("device {id:?}: {e}"))).ok()?;
    (cx.errors.len() == errors).then_some(group)
}

/// The cells' names: `names` in order, or `name` for a single cell, or `name.0`, `name.1`, ...
/// (nothing given: the address, `0x1000`).
fn raw_names(cx: &mut Cx<'_>, r: &raw::Raw, address: u16, count: u16, format: Format) -> Option<Vec<(u16, String)>> {
    let width = format.width().max(1);
    let cells = count / width;
    let at = |i: u16| address.saturating_add(i.saturating_mul(width));
    if !r.names.is_empty() {
        if r.names.len() != usize::from(cells) {
            let span = r.names.first().map_or(0..0, Spanned::span);
            cx.at(span, format!("{} names for {cells} cells of {}", r.names.len(), format.name()));
            return None;
        }
        return Some((0..cells).zip(&r.names).map(|(i, n)| (at(i), n.get_ref().clone())).collect());
    }
    Some(match &r.name {
        Some(name) if cells == 1 => vec![(address, name.get_ref().clone())],
        Some(name) => (0..cells).map(|i| (at(i), format!("{}.{i}", name.get_ref()))).collect(),
        None => Vec::new(),
    })
}

/// A metric name is used once per device; the second use is reported where it was asked for.
fn check_metric_names(cx: &mut Cx<'_>, id: &str, profile: Option<&Profile>, groups: &[(Group, f64, Source<'_>)]) {
    let mut seen: HashMap<&str, Range<usize>> = HashMap::new();
    for (group, _, source) in groups {
        for cell in &group.cells {
            let span = source_span(profile, source, cell);
            if matches!(source, Source::Points(_))
                && let Some(problem) = cx.unfit_metric_name(&cell.name)
            {
                cx.at(span.clone(), format!("device {id:?}: {problem} (the profile's code)"));
            }
            if let Some(first) = seen.get(cell.name.as_str()) {
                let line = cx.line_of(first);
                cx.at(
                    span,
                    format!("device {id:?}: metric {:?} is polled twice (first at line {line}); a device's metric names are unique", cell.name),
                );
            } else {
                seen.insert(&cell.name, span);
            }
        }
    }
}

/// Where a cell was asked for: the name that matched its point, or the name given to it in
/// its range (else the range).
fn source_span(profile: Option<&Profile>, source: &Source<'_>, cell: &Cell) -> Range<usize> {
    match source {
        Source::Raw(range) => {
            let r = range.get_ref();
            let named = r.names.iter().find(|n| *n.get_ref() == cell.name).or(r.name.as_ref());
            named.map_or_else(|| range.span(), Spanned::span)
        }
        Source::Points(set) => {
            let point = &cell.point;
            let same = |p: &&Point| p.table == point.table && p.address == point.address;
            let by_name = profile.and_then(|profile| {
                set.points
                    .iter()
                    .find(|n| profile.find(n.get_ref()).iter().any(same))
                    .or_else(|| set.groups.iter().find(|g| profile.group(g.get_ref()).iter().any(same)))
            });
            by_name.map_or_else(|| set.span.clone(), Spanned::span)
        }
    }
}

/// `[group][cell]`: the cell's own (`deadbands`), else its poll's or range's, else the
/// device's.
fn deadbands(cx: &mut Cx<'_>, d: &raw::Device, groups: &[(Group, f64, Source<'_>)]) -> Vec<Vec<f64>> {
    let mut own: Vec<(&str, f64)> = Vec::new();
    for (name, band) in &d.deadbands {
        let value = cx.deadband(&format!("deadbands.{}", name.get_ref()), band);
        let polled = groups.iter().flat_map(|(g, _, _)| &g.cells).any(|c| c.name.eq_ignore_ascii_case(name.get_ref()));
        if polled {
            own.push((name.get_ref(), value));
        } else {
            let names: Vec<&str> = groups.iter().flat_map(|(g, _, _)| &g.cells).map(|c| c.name.as_str()).collect();
            cx.at(
                name.span(),
                format!(
                    "deadbands: device {:?} polls no {:?}; it polls {}",
                    d.id.get_ref(),
                    name.get_ref(),
                    names.join(", ")
                ),
            );
        }
    }
    groups
        .iter()
        .map(|(group, band, _)| {
            group
                .cells
                .iter()
                .map(|c| own.iter().find(|(n, _)| c.name.eq_ignore_ascii_case(n)).map_or(*band, |(_, b)| *b))
                .collect()
        })
        .collect()
}
