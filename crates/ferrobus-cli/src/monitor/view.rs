//! Drawing the monitor: the panes (title, status line, grid), the traffic pane, the trend
//! chart, the prompt and the keys. Pure: it draws an [`App`] into a frame.

use std::fmt::Write as _;

use ferrobus_profile::WireWrite;
use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Axis, Block, Borders, Chart, Dataset, GraphType, Paragraph};

use super::model::{App, Definition, Mode};

/// The width of one grid cell, with the gap after it.
const CELL_WIDTH: u16 = 26;

/// The keys, as the bottom line lists them.
pub(crate) const KEYS: &str = "q quit  Tab pane  ←↑↓→ cell  e edit  f format  o order  a alias  t trend  p pause  r reset  \
     Space traffic  PgUp/PgDn scroll  s save";

/// Draws the whole screen.
pub(crate) fn draw(frame: &mut Frame<'_>, app: &App) {
    let area = frame.area();
    let bottom = if area.height >= 20 { area.height / 3 } else { 5 };
    let [header, panes, lower, prompt, keys] = Layout::vertical([
        Constraint::Length(1),
        Constraint::Min(3),
        Constraint::Length(bottom),
        Constraint::Length(1),
        Constraint::Length(if area.width >= 130 { 1 } else { 2 }),
    ])
    .areas(area);
    draw_header(frame, header, app);
    draw_panes(frame, panes, app);
    if app.trends.is_empty() {
        draw_traffic(frame, lower, app);
    } else {
        let [traffic, trend] =
            Layout::horizontal([Constraint::Percentage(55), Constraint::Percentage(45)]).areas(lower);
        draw_traffic(frame, traffic, app);
        draw_trend(frame, trend, app);
    }
    draw_prompt(frame, prompt, app);
    frame.render_widget(
        Paragraph::new(KEYS).wrap(ratatui::widgets::Wrap { trim: true }).style(Style::new().fg(Color::Cyan)),
        keys,
    );
}

fn draw_header(frame: &mut Frame<'_>, area: Rect, app: &App) {
    let state = if app.paused { "PAUSED" } else { "polling" };
    let line = Line::from(vec![
        Span::styled("ferrobus monitor", Style::new().add_modifier(Modifier::BOLD)),
        Span::raw(format!("  {}  {state}", app.target)),
    ]);
    frame.render_widget(Paragraph::new(line), area);
}

fn draw_panes(frame: &mut Frame<'_>, area: Rect, app: &App) {
    if app.panes.is_empty() {
        return;
    }
    let constraints = app.panes.iter().map(|_| Constraint::Fill(1));
    let areas = Layout::vertical(constraints).split(area);
    for (index, (pane, rect)) in app.panes.iter().zip(areas.iter()).enumerate() {
        draw_pane(frame, *rect, app, index, pane);
    }
}

/// The pane's title: `unit 1 holding 0x0000 ×10 every 500 ms`.
pub(crate) fn title(pane: &Definition) -> String {
    let reads = match pane.reads.len() {
        0 | 1 => String::new(),
        n => format!(" in {n} reads"),
    };
    format!(
        " unit {} {} {:#06x} ×{}{reads} every {} ms ",
        pane.unit,
        pane.table_name(),
        pane.address,
        pane.count,
        pane.every.as_millis()
    )
}

/// The status line: `Tx 12  Err 1 (timeout 1, CRC 0, exception 0, other 0)  last 3.2 ms`.
pub(crate) fn status(pane: &Definition) -> String {
    let c = &pane.counters;
    let mut text = format!(
        "Tx {}  Err {} (timeout {}, CRC {}, exception {}, other {})",
        c.tx,
        c.errors(),
        c.timeouts,
        c.crc,
        c.exceptions,
        c.other
    );
    match pane.last_response {
        Some(t) => {
            let _ = write!(text, "  last {:.1} ms", t.as_secs_f64() * 1000.0);
        }
        None => text.push_str("  last -"),
    }
    text
}

fn draw_pane(frame: &mut Frame<'_>, area: Rect, app: &App, index: usize, pane: &Definition) {
    let focused = index == app.pane;
    let border = if focused { Style::new().fg(Color::Yellow) } else { Style::new() };
    let block = Block::new().borders(Borders::ALL).border_style(border).title(title(pane));
    let inner = block.inner(area);
    if inner.height == 0 {
        frame.render_widget(block, area);
        return;
    }
    let mut lines = vec![Line::from(status(pane))];
    if let Some(error) = &pane.last_error
        && pane.counters.errors() > 0
    {
        lines.push(Line::styled(format!("last error: {error}"), Style::new().fg(Color::Red)));
    }
    let texts: Vec<String> = pane
        .cells
        .iter()
        .map(|cell| {
            let value = cell.show(pane).unwrap_or_else(|| "-".to_string());
            let name = if cell.alias.is_empty() { cell.format.name() } else { cell.alias.clone() };
            let mark = if cell.trended { '*' } else { ' ' };
            format!("{mark}{:04x} {:<8.8} {:>10} ", cell.point.address, name, value)
        })
        .collect();
    let width = texts.iter().map(|t| t.chars().count()).max().unwrap_or(1).max(usize::from(CELL_WIDTH));
    let columns = (usize::from(inner.width) / width).max(1);
    if focused {
        app.columns.set(columns);
    }
    let rows_free = usize::from(inner.height).saturating_sub(lines.len()).max(1);
    // Scroll the grid so that the selected cell is in view.
    let selected_row = if focused { app.cell / columns } else { 0 };
    let first_row = selected_row.saturating_sub(rows_free.saturating_sub(1));
    let rows = texts.len().div_ceil(columns);
    let block = if rows > rows_free {
        let last = (first_row + rows_free).min(rows);
        block.title_bottom(format!(" rows {}-{last} of {rows} (↑↓ scroll) ", first_row + 1))
    } else {
        block
    };
    frame.render_widget(block, area);
    let cells: Vec<(usize, &String)> = texts.iter().enumerate().collect();
    for row in cells.chunks(columns).skip(first_row).take(rows_free) {
        let mut spans = Vec::new();
        for &(i, text) in row {
            let style =
                if focused && i == app.cell { Style::new().add_modifier(Modifier::REVERSED) } else { Style::new() };
            spans.push(Span::styled(format!("{text:<width$}"), style));
        }
        lines.push(Line::from(spans));
    }
    frame.render_widget(Paragraph::new(lines), inner);
}

fn hex(bytes: &[u8]) -> String {
    let mut text = String::with_capacity(bytes.len() * 3);
    for (i, b) in bytes.iter().enumerate() {
        if i > 0 {
            text.push(' ');
        }
        let _ = write!(text, "{b:02X}");
    }
    text
}

fn draw_traffic(frame: &mut Frame<'_>, area: Rect, app: &App) {
    let t = &app.traffic;
    let mut title = String::from(" traffic ");
    if t.paused {
        let _ = write!(title, "(paused, {} not shown) ", t.missed);
    }
    if t.scroll > 0 {
        let _ = write!(title, "(scrolled up {}) ", t.scroll);
    }
    let block = Block::new().borders(Borders::ALL).title(title);
    let inner = block.inner(area);
    frame.render_widget(block, area);
    let rows = usize::from(inner.height);
    let end = t.lines.len().saturating_sub(t.scroll);
    let start = end.saturating_sub(rows);
    let lines: Vec<Line<'_>> = t
        .lines
        .range(start..end)
        .map(|l| {
            let style = match l.direction {
                "Tx" => Style::new().fg(Color::Green),
                "Rx" => Style::new(),
                _ => Style::new().fg(Color::Red),
            };
            Line::styled(
                format!("{:>8.3} {} u{} {}  {}", l.at.as_secs_f64(), l.direction, l.unit, hex(&l.bytes), l.decode),
                style,
            )
        })
        .collect();
    frame.render_widget(Paragraph::new(lines), inner);
}

/// The chart's bounds from the data: the span of the values, widened by a tenth (or by one
/// around a flat line), never forced to zero.
pub(crate) fn bounds(values: impl Iterator<Item = f64>) -> Option<[f64; 2]> {
    let (lo, hi) = values.filter(|v| v.is_finite()).fold(None, |acc: Option<(f64, f64)>, v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })?;
    let pad = if hi > lo { (hi - lo) / 10.0 } else { 1.0 };
    Some([lo - pad, hi + pad])
}

fn draw_trend(frame: &mut Frame<'_>, area: Rect, app: &App) {
    let colors = [Color::Yellow, Color::Cyan, Color::Magenta, Color::Green];
    let data: Vec<Vec<(f64, f64)>> = app.trends.iter().map(|t| t.samples.iter().copied().collect()).collect();
    let names: Vec<String> = app
        .trends
        .iter()
        .map(|t| {
            app.panes
                .get(t.pane)
                .and_then(|p| p.cells.get(t.cell))
                .map(|c| if c.alias.is_empty() { format!("{:04x}", c.point.address) } else { c.alias.clone() })
                .unwrap_or_default()
        })
        .collect();
    let datasets = data
        .iter()
        .zip(names)
        .zip(colors.iter().cycle())
        .map(|((points, name), color)| {
            Dataset::default()
                .name(name)
                .marker(Marker::Braille)
                .graph_type(GraphType::Line)
                .style(Style::new().fg(*color))
                .data(points)
        })
        .collect();
    let x = bounds(data.iter().flatten().map(|p| p.0)).unwrap_or([0.0, 1.0]);
    let y = bounds(data.iter().flatten().map(|p| p.1)).unwrap_or([0.0, 1.0]);
    let label = |v: f64| Span::raw(format!("{v:.1}"));
    let chart = Chart::new(datasets)
        .block(Block::new().borders(Borders::ALL).title(" trend "))
        .x_axis(Axis::default().bounds(x).labels([label(x[0]), label(x[1])]))
        .y_axis(Axis::default().bounds(y).labels([label(y[0]), label(y[1])]));
    frame.render_widget(chart, area);
}

fn draw_prompt(frame: &mut Frame<'_>, area: Rect, app: &App) {
    let selected = app.selected().map(|(p, c)| format!("unit {} {:#06x}", p.unit, c.point.address)).unwrap_or_default();
    let line = match &app.mode {
        Mode::Normal => match &app.message {
            Some(m) => Line::styled(m.clone(), Style::new().fg(Color::Yellow)),
            None => Line::from(""),
        },
        Mode::Edit(text) => Line::from(format!("write {selected} = {text}_   (Enter: check, Esc: cancel)")),
        Mode::Alias(text) => Line::from(format!("alias of {selected}: {text}_   (Enter: set, Esc: cancel)")),
        Mode::Confirm { text, request, .. } => {
            let what = match request {
                WireWrite::Coil { on, .. } | WireWrite::OneOfCoils { on, .. } => format!("coil {}", u8::from(*on)),
                WireWrite::Register { value, .. } => format!("registers [{value:#06x}]"),
                WireWrite::Registers { values, .. } => {
                    format!("registers [{}]", values.iter().map(|r| format!("{r:#06x}")).collect::<Vec<_>>().join(" "))
                }
            };
            Line::styled(format!("write {text} ({what}) to {selected}? y/n"), Style::new().fg(Color::Yellow))
        }
    };
    frame.render_widget(Paragraph::new(line), area);
}
