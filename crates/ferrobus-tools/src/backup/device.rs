//! Reading and writing parameters on the device: the reads in the profile's read plan
//! ([`ferrobus_profile::plan`]), the writes, and failures worded with the profile's meaning of
//! the device's exception codes. The caller's [`Watch`] can stop the reads between two
//! requests (Ctrl-C) and hears of their progress (a progress bar).

use std::collections::BTreeMap;
use std::future::Future;

use ferrobus_profile::{Extent, Point, Profile, Table, Value};
use ferrobus_proto::codes::{ReadDeviceIdCode, device_object};

use super::view::{Identification, View};
use crate::write::WriteError;
use ferrobus::client::Client;
use ferrobus::error::Error;

/// What reads and writes watch besides the bus: a stop, and the progress.
pub trait Watch {
    /// Completes when the work is to stop (Ctrl-C, say): the request in flight is dropped and
    /// nothing more is sent. Never completes for work that runs to its end.
    fn stop(&mut self) -> impl Future<Output = ()>;

    /// `done` more parameters have their outcome.
    fn progress(&mut self, done: u64) {
        let _ = done;
    }

    /// The parameter `code` is being written.
    fn started(&mut self, code: &str) {
        let _ = code;
    }
}

/// A [`Watch`] that never stops the work and ignores its progress.
#[derive(Clone, Copy, Debug, Default)]
pub struct Unwatched;

impl Watch for Unwatched {
    fn stop(&mut self) -> impl Future<Output = ()> {
        std::future::pending()
    }
}

/// Runs `work` unless `watch` stops it first; `None` if it did.
pub(super) async fn unless<F: Future>(watch: &mut impl Watch, work: F) -> Option<F::Output> {
    tokio::select! {
        biased;
        () = watch.stop() => None,
        done = work => Some(done),
    }
}

/// The device a backup reads and a restore writes: a client and the unit.
#[derive(Clone, Copy, Debug)]
pub struct Target<'a> {
    /// The client of the bus.
    pub client: &'a Client,
    /// The unit.
    pub unit: u8,
}

/// What the reads found: each parameter's registers (a bit as 0 or 1), or why it was not read.
#[derive(Debug, Default)]
pub struct Readings {
    /// By code.
    pub values: BTreeMap<String, Result<Vec<u16>, String>>,
    /// The requests sent.
    pub requests: usize,
    /// The planned requests, before any retry of a refused one point by point.
    pub planned: usize,
    /// The error that stopped the reads (no reply, the port lost), if one did.
    pub stopped: Option<Error>,
    /// Whether Ctrl-C (or SIGTERM) stopped the reads.
    pub interrupted: bool,
    /// How long the reads took, from the first request to the last reply.
    pub elapsed: std::time::Duration,
}

impl Readings {
    /// Why the parameters not yet read will not be, once the reads have stopped.
    fn why_stopped(&self, view: &View) -> Option<String> {
        if self.interrupted {
            return Some(INTERRUPTED.to_string());
        }
        self.stopped.as_ref().map(|error| format!("not read: the reads stopped after {}", describe(error, view)))
    }

    /// The codes of `params` that were read, and of those that were not.
    pub fn split<'p>(&self, params: &[&'p Point]) -> (Vec<&'p str>, Vec<&'p str>) {
        params.iter().map(|p| p.code.as_str()).partition(|code| self.values.get(*code).is_some_and(Result::is_ok))
    }
}

/// Why a parameter was not read when Ctrl-C stopped the reads.
pub const INTERRUPTED: &str = "not read: interrupted (Ctrl-C or SIGTERM)";

/// Reads `params` in the planned requests, with a progress bar on a terminal. A request
/// refused with an exception is read again point by point, so that only the points the
/// device refuses are marked; after an error that is not an exception (no reply, a lost port)
/// or an interruption nothing more is sent and the rest are marked not read, with why.
pub async fn read(target: Target<'_>, view: &View, params: &[&Point], watch: &mut impl Watch) -> Readings {
    let began = std::time::Instant::now();
    let mut readings = Readings::default();
    for table in [Table::Holding, Table::Input, Table::Coils, Table::DiscreteInputs] {
        let here: Vec<&Point> = params.iter().copied().filter(|p| p.table == table).collect();
        if !here.is_empty() {
            let mut reads = Reads { target, view, watch: &mut *watch, readings: &mut readings };
            reads.table_points(table, &here).await;
        }
    }
    // Points of a request cut short by a stop inside the point-by-point reads.
    if let Some(why) = readings.why_stopped(view) {
        for p in params {
            readings.values.entry(p.code.clone()).or_insert_with(|| Err(why.clone()));
        }
    }
    readings.elapsed = began.elapsed();
    readings
}

/// One table's reads under way: where, with what profile, watched by what, into what.
struct Reads<'r, W> {
    target: Target<'r>,
    view: &'r View,
    watch: &'r mut W,
    readings: &'r mut Readings,
}

impl<W: Watch> Reads<'_, W> {
    /// Reads the points `here` of `table` in the planned requests.
    async fn table_points(&mut self, table: Table, here: &[&Point]) {
        let (view, target) = (self.view, self.target);
        let profile = &view.profile;
        let wanted: Vec<Extent> = here.iter().map(|p| Extent { start: p.address, width: p.width }).collect();
        let requests = match ferrobus_profile::plan(
            &wanted,
            &profile.mapped(table),
            &profile.spans(table),
            profile.read_limit(table),
        ) {
            Ok(requests) => requests,
            Err(error) => {
                for p in here {
                    self.readings.values.insert(p.code.clone(), Err(format!("no read plan: {error}")));
                }
                return;
            }
        };
        self.readings.planned += requests.len();
        for ferrobus_profile::Request { start, count } in requests {
            let inside: Vec<&Point> = here
                .iter()
                .copied()
                .filter(|p| p.address >= start && u32::from(p.address) < u32::from(start) + u32::from(count))
                .collect();
            let done = u64::try_from(inside.len()).unwrap_or(0);
            if let Some(why) = self.readings.why_stopped(view) {
                for p in inside {
                    self.readings.values.insert(p.code.clone(), Err(why.clone()));
                }
                continue;
            }
            self.readings.requests += 1;
            tracing::info!(table = table.name(), start, count, "read request");
            let Some(result) = unless(self.watch, read_table(target, table, start, count)).await else {
                self.readings.interrupted = true;
                continue;
            };
            match result {
                Ok(items) => {
                    for p in inside {
                        let from = usize::from(p.address - start);
                        let words = items.get(from..from + usize::from(p.width)).map(<[u16]>::to_vec);
                        let value = words.ok_or_else(|| "the reply was short".to_string());
                        self.readings.values.insert(p.code.clone(), value);
                    }
                }
                Err(error @ Error::Exception { .. }) if inside.len() > 1 => {
                    tracing::info!(start, count, %error, "refused; reading point by point");
                    self.one_by_one(table, &inside).await;
                }
                Err(error) => {
                    let why = describe(&error, view);
                    for p in &inside {
                        self.readings.values.insert(p.code.clone(), Err(why.clone()));
                    }
                    if !matches!(error, Error::Exception { .. }) {
                        self.readings.stopped = Some(error);
                    }
                }
            }
            self.watch.progress(done);
        }
    }

    /// Reads each of `points` on its own (after the device refused them together).
    async fn one_by_one(&mut self, table: Table, points: &[&Point]) {
        let (view, target) = (self.view, self.target);
        for p in points {
            self.readings.requests += 1;
            let Some(result) = unless(self.watch, read_table(target, table, p.address, p.width)).await else {
                self.readings.interrupted = true;
                return;
            };
            let value = match result {
                Ok(items) => Ok(items),
                Err(error @ Error::Exception { .. }) => Err(describe(&error, view)),
                Err(error) => {
                    let why = describe(&error, view);
                    self.readings.stopped = Some(error);
                    self.readings.values.insert(p.code.clone(), Err(why));
                    return;
                }
            };
            self.readings.values.insert(p.code.clone(), value);
        }
    }
}

async fn read_table(target: Target<'_>, table: Table, start: u16, count: u16) -> Result<Vec<u16>, Error> {
    let (client, unit) = (target.client, target.unit);
    let bits = |b: Vec<bool>| b.into_iter().map(u16::from).collect();
    match table {
        Table::Holding => client.read_holding_registers(unit, start, count).await,
        Table::Input => client.read_input_registers(unit, start, count).await,
        Table::Coils => client.read_coils(unit, start, count).await.map(bits),
        Table::DiscreteInputs => client.read_discrete_inputs(unit, start, count).await.map(bits),
    }
}

/// Writes raw value `raw` to `point` in the one request [`Point::wire_write`] chooses with
/// `profile`'s functions and write limit ([`crate::write::send`]); the guard is the restore's,
/// applied to every parameter first.
pub async fn write(target: Target<'_>, profile: &Profile, point: &Point, raw: &Value) -> Result<(), WriteError> {
    let request = point.wire_write(raw, &profile.write_rules())?;
    crate::write::send(target.client, target.unit, &request).await?;
    Ok(())
}

/// An error in the user's words, with the profile's meaning of an exception code.
pub fn describe(error: &Error, view: &View) -> String {
    match error {
        Error::Exception { code, .. } => match view.meaning(code.value()) {
            Some(meaning) => format!("exception {code}: {meaning}"),
            None => format!("exception {code}"),
        },
        other => other.to_string(),
    }
}

/// How the device identifies itself: FC2B/0E's basic objects, or FC11's data, if the profile
/// says it has them, and how (`FC2B/0E`, `FC11`, or why not). A refusal is recorded, not an
/// error; no reply is.
pub async fn identify(target: Target<'_>, view: &View) -> Result<(String, Vec<(String, String)>), Error> {
    let (client, unit) = (target.client, target.unit);
    match view.identification() {
        Identification::None => {
            Ok(("none: the profile says the device has no identification (FC2B/0E, FC11)".into(), Vec::new()))
        }
        Identification::DeviceId => match client.read_device_identification(unit, ReadDeviceIdCode::Basic, 0).await {
            Ok(info) => {
                let objects = info
                    .objects
                    .into_iter()
                    .map(|(id, bytes)| {
                        let name = device_object::name(id).map_or_else(|| format!("object-0x{id:02X}"), str::to_string);
                        (name, String::from_utf8_lossy(&bytes).into_owned())
                    })
                    .collect();
                Ok(("FC2B/0E".into(), objects))
            }
            Err(error @ Error::Exception { .. }) => {
                Ok((format!("FC2B/0E refused: {}", describe(&error, view)), Vec::new()))
            }
            Err(error) => Err(error),
        },
        Identification::ServerId => match client.report_server_id(unit).await {
            Ok(data) => Ok(("FC11".into(), vec![("server_id".into(), hex(&data))])),
            Err(error @ Error::Exception { .. }) => {
                Ok((format!("FC11 refused: {}", describe(&error, view)), Vec::new()))
            }
            Err(error) => Err(error),
        },
    }
}

/// Bytes in hex, `01 A0 FF`.
fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02X}")).collect::<Vec<_>>().join(" ")
}
