//! The keys: what each does to the [`App`], and the requests (a write, a save) it leaves for
//! the IO loop.

use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyEventKind, KeyModifiers};

use ferrobus_profile::{Table, Value, WireWrite};

use super::model::{App, Mode};

/// What the IO loop has to do after a key.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Action {
    /// Nothing.
    None,
    /// Write to the device.
    Write(Asked),
    /// Save the session file.
    Save,
    /// The counters were reset (the poller's too).
    Reset,
}

/// A write the user confirmed.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Asked {
    /// The pane (for its unit).
    pub(crate) pane: usize,
    /// The cell (for its point, which the write guard checks right before the write).
    pub(crate) cell: usize,
    /// The raw value, as typed.
    pub(crate) raw: Value,
    /// What was typed.
    pub(crate) text: String,
    /// The request that writes it.
    pub(crate) request: WireWrite,
}

/// Applies `key`.
pub(crate) fn handle(app: &mut App, key: KeyEvent) -> Action {
    if key.kind == KeyEventKind::Release {
        return Action::None;
    }
    if key.modifiers.contains(KeyModifiers::CONTROL) && key.code == KeyCode::Char('c') {
        app.quit = true;
        return Action::None;
    }
    match std::mem::replace(&mut app.mode, Mode::Normal) {
        Mode::Normal => normal(app, key.code),
        Mode::Edit(text) => {
            app.mode = typing(text, key.code, Mode::Edit, |text| check(app, text));
            Action::None
        }
        Mode::Alias(text) => {
            app.mode = typing(text, key.code, Mode::Alias, |text| {
                let (pane, cell) = (app.pane, app.cell);
                if let Some(c) = app.panes.get_mut(pane).and_then(|p| p.cells.get_mut(cell)) {
                    c.alias = text.trim().to_string();
                }
                Mode::Normal
            });
            Action::None
        }
        Mode::Confirm { text, raw, request } => {
            if let KeyCode::Char('y' | 'Y') = key.code {
                app.message = Some(format!("writing {text} to {:#06x}", request.address()));
                return Action::Write(Asked { pane: app.pane, cell: app.cell, raw, text, request });
            }
            app.message = Some("write cancelled".into());
            Action::None
        }
    }
}

/// A line of text being typed: Enter hands it to `done`, Esc cancels.
fn typing(mut text: String, code: KeyCode, again: fn(String) -> Mode, done: impl FnOnce(&str) -> Mode) -> Mode {
    match code {
        KeyCode::Enter => done(&text),
        KeyCode::Esc => Mode::Normal,
        KeyCode::Backspace => {
            text.pop();
            again(text)
        }
        KeyCode::Char(c) if text.chars().count() < 40 => {
            text.push(c);
            again(text)
        }
        _ => again(text),
    }
}

/// Checks a typed value against the cell's point (its type, range and access): the
/// confirmation, or back to normal with the reason.
fn check(app: &mut App, text: &str) -> Mode {
    let Some((pane, cell)) = app.selected() else { return Mode::Normal };
    if !matches!(pane.table, Table::Holding | Table::Coils) {
        app.message = Some(format!("{} are read-only", pane.table_name()));
        return Mode::Normal;
    }
    let written = cell.point.prepare_write(text).map_err(Into::into).and_then(|raw| {
        let request = cell.point.wire_write(&raw, &app.rules)?;
        Ok::<_, ferrobus_profile::Refusal>((raw, request))
    });
    match written {
        Ok((raw, request)) => Mode::Confirm { text: text.trim().to_string(), raw, request },
        Err(e) => {
            app.message = Some(format!("not written: {e}"));
            Mode::Normal
        }
    }
}

fn normal(app: &mut App, code: KeyCode) -> Action {
    app.message = None;
    let cells = app.panes.get(app.pane).map_or(0, |p| p.cells.len());
    let last = cells.saturating_sub(1);
    let columns = app.columns.get().max(1);
    match code {
        KeyCode::Char('q') | KeyCode::Esc => app.quit = true,
        KeyCode::Tab => {
            app.pane = (app.pane + 1) % app.panes.len().max(1);
            app.cell = 0;
        }
        KeyCode::BackTab => {
            app.pane = app.pane.checked_sub(1).unwrap_or(app.panes.len().saturating_sub(1));
            app.cell = 0;
        }
        KeyCode::Right | KeyCode::Char('l') => app.cell = app.cell.saturating_add(1).min(last),
        KeyCode::Left | KeyCode::Char('h') => app.cell = app.cell.saturating_sub(1),
        KeyCode::Down | KeyCode::Char('j') => app.cell = app.cell.saturating_add(columns).min(last),
        KeyCode::Up | KeyCode::Char('k') => app.cell = app.cell.saturating_sub(columns),
        KeyCode::Char('e') | KeyCode::Enter => app.mode = Mode::Edit(String::new()),
        KeyCode::Char('a') => app.mode = Mode::Alias(String::new()),
        KeyCode::Char('f') => with_cell(app, |c| c.set_format(c.format.next())),
        KeyCode::Char('o') => with_cell(app, |c| c.set_format(c.format.next_order())),
        KeyCode::Char('t') => app.toggle_trend(),
        KeyCode::Char('p') => app.paused = !app.paused,
        KeyCode::Char('r') => {
            app.reset_counters();
            return Action::Reset;
        }
        KeyCode::Char(' ') => {
            app.traffic.paused = !app.traffic.paused;
            if !app.traffic.paused {
                app.traffic.missed = 0;
            }
        }
        KeyCode::PageUp => {
            app.traffic.scroll = (app.traffic.scroll + 5).min(app.traffic.lines.len().saturating_sub(1));
        }
        KeyCode::PageDown => app.traffic.scroll = app.traffic.scroll.saturating_sub(5),
        KeyCode::Char('s') => return Action::Save,
        _ => {}
    }
    Action::None
}

fn with_cell(app: &mut App, f: impl FnOnce(&mut super::model::Cell)) {
    let (pane, cell) = (app.pane, app.cell);
    if let Some(c) = app.panes.get_mut(pane).and_then(|p| p.cells.get_mut(cell)) {
        f(c);
    }
}
