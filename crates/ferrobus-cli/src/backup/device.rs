//! Reading and writing parameters on the device: the read plan, the reads, the writes, and
//! failures worded with the profile's meaning of the device's exception codes.

use std::collections::BTreeMap;

use ferrobus::Error;

use super::param::{Param, Table};
use super::view::View;
use crate::connect::Session;

/// The fewest requests that read every point of one table: `points` are (first address,
/// registers or bits), disjoint; each request holds at most `limit` items, never splits a
/// point, and covers only addresses that `answers` (a mapped address or one inside a span).
///
/// Greedy from the lowest point is optimal here: whether a run of consecutive points fits one
/// request only gets easier as the run shrinks, so a request that takes as many points as fit
/// never leaves more requests to the rest.
pub(crate) fn plan(points: &[(u16, u16)], limit: u16, answers: impl Fn(u16) -> bool) -> Vec<(u16, u16)> {
    let mut sorted: Vec<(u32, u32)> = points.iter().map(|&(a, w)| (u32::from(a), u32::from(w))).collect();
    sorted.sort_unstable();
    let limit = u32::from(limit.max(1));
    let mut requests: Vec<(u16, u16)> = Vec::new();
    let mut current: Option<(u32, u32)> = None; // (start, end exclusive)
    for (start, width) in sorted {
        let end = start.saturating_add(width);
        current = match current {
            Some((first, last)) if end <= last => Some((first, last)),
            Some((first, last))
                if end.saturating_sub(first) <= limit
                    && (last..start).all(|a| u16::try_from(a).is_ok_and(&answers)) =>
            {
                Some((first, end))
            }
            other => {
                if let Some(done) = other {
                    requests.push(narrow(done));
                }
                Some((start, end))
            }
        };
    }
    if let Some(done) = current {
        requests.push(narrow(done));
    }
    requests
}

fn narrow((start, end): (u32, u32)) -> (u16, u16) {
    (u16::try_from(start).unwrap_or(u16::MAX), u16::try_from(end.saturating_sub(start)).unwrap_or(u16::MAX))
}

/// What the reads found: each parameter's registers (a bit as 0 or 1), or why it was not read.
#[derive(Debug, Default)]
pub(crate) struct Readings {
    /// By code.
    pub(crate) values: BTreeMap<String, Result<Vec<u16>, String>>,
    /// The requests sent.
    pub(crate) requests: usize,
    /// The planned requests, before any retry of a refused one point by point.
    pub(crate) planned: usize,
    /// The error that stopped the reads (no reply, the port lost), if one did.
    pub(crate) stopped: Option<Error>,
}

/// Reads `params` in the planned requests. A request refused with an exception is read again
/// point by point, so that only the points the device refuses are marked; after an error that
/// is not an exception (no reply, a lost port) nothing more is sent and the rest are marked
/// not read.
pub(crate) async fn read(session: &Session, view: &View, params: &[&Param]) -> Readings {
    let mut readings = Readings::default();
    for table in [Table::Holding, Table::Input, Table::Coils, Table::Discrete] {
        let here: Vec<&Param> = params.iter().copied().filter(|p| p.table == table).collect();
        if here.is_empty() {
            continue;
        }
        let points: Vec<(u16, u16)> = here.iter().map(|p| (p.wire, p.width)).collect();
        let limit = if table.is_bits() { view.read_bits } else { view.read_registers };
        let requests = plan(&points, limit, |a| view.answers(table, a));
        readings.planned += requests.len();
        for (start, count) in requests {
            let inside: Vec<&Param> = here
                .iter()
                .copied()
                .filter(|p| p.wire >= start && u32::from(p.wire) < u32::from(start) + u32::from(count))
                .collect();
            if let Some(error) = &readings.stopped {
                let why = format!("not read: the reads stopped after {}", describe(error, view));
                for p in inside {
                    readings.values.insert(p.code.clone(), Err(why.clone()));
                }
                continue;
            }
            readings.requests += 1;
            match read_table(session, table, start, count).await {
                Ok(items) => {
                    for p in inside {
                        let from = usize::from(p.wire - start);
                        let words = items.get(from..from + usize::from(p.width)).map(<[u16]>::to_vec);
                        let value = words.ok_or_else(|| "the reply was short".to_string());
                        readings.values.insert(p.code.clone(), value);
                    }
                }
                Err(error @ Error::Exception { .. }) if inside.len() > 1 => {
                    tracing::info!(start, count, %error, "refused; reading point by point");
                    for p in inside {
                        readings.requests += 1;
                        let value = match read_table(session, table, p.wire, p.width).await {
                            Ok(items) => Ok(items),
                            Err(error @ Error::Exception { .. }) => Err(describe(&error, view)),
                            Err(error) => {
                                let why = describe(&error, view);
                                readings.stopped = Some(error);
                                Err(why)
                            }
                        };
                        readings.values.insert(p.code.clone(), value);
                        if readings.stopped.is_some() {
                            break;
                        }
                    }
                }
                Err(error) => {
                    let why = describe(&error, view);
                    for p in &inside {
                        readings.values.insert(p.code.clone(), Err(why.clone()));
                    }
                    if !matches!(error, Error::Exception { .. }) {
                        readings.stopped = Some(error);
                    }
                }
            }
        }
    }
    // Points of a request cut short by a stop inside the point-by-point reads.
    if let Some(error) = &readings.stopped {
        let why = format!("not read: the reads stopped after {}", describe(error, view));
        for p in params {
            readings.values.entry(p.code.clone()).or_insert_with(|| Err(why.clone()));
        }
    }
    readings
}

async fn read_table(session: &Session, table: Table, start: u16, count: u16) -> Result<Vec<u16>, Error> {
    let (client, unit) = (&session.client, session.unit);
    let bits = |b: Vec<bool>| b.into_iter().map(u16::from).collect();
    match table {
        Table::Holding => client.read_holding_registers(unit, start, count).await,
        Table::Input => client.read_input_registers(unit, start, count).await,
        Table::Coils => client.read_coils(unit, start, count).await.map(bits),
        Table::Discrete => client.read_discrete_inputs(unit, start, count).await.map(bits),
    }
}

/// Writes `words` to `param`: FC05 for a coil, FC06 for one register, FC10 for more.
pub(crate) async fn write(session: &Session, param: &Param, words: &[u16]) -> Result<(), Error> {
    let (client, unit) = (&session.client, session.unit);
    match (param.table, words) {
        (Table::Coils, [bit]) => client.write_single_coil(unit, param.wire, *bit != 0).await,
        (_, [one]) => client.write_single_register(unit, param.wire, *one).await,
        _ => client.write_multiple_registers(unit, param.wire, words).await,
    }
}

/// An error in the user's words, with the profile's meaning of an exception code.
pub(crate) fn describe(error: &Error, view: &View) -> String {
    match error {
        Error::Exception { code, .. } => match view.meaning(code.value()) {
            Some(meaning) => format!("exception {code}: {meaning}"),
            None => format!("exception {code}"),
        },
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::plan;

    /// The fewest requests by dynamic programming over the sorted points.
    fn optimum(points: &[(u16, u16)], limit: u16, answers: &dyn Fn(u16) -> bool) -> Option<usize> {
        let mut p = points.to_vec();
        p.sort_unstable();
        let n = p.len();
        let mut best = vec![usize::MAX; n + 1];
        best[0] = 0;
        for j in 1..=n {
            for i in 0..j {
                let start = u32::from(p[i].0);
                let end = u32::from(p[j - 1].0) + u32::from(p[j - 1].1);
                let holes_ok = (i..j - 1).all(|k| {
                    (u32::from(p[k].0) + u32::from(p[k].1)..u32::from(p[k + 1].0))
                        .all(|a| u16::try_from(a).is_ok_and(answers))
                });
                if end - start <= u32::from(limit) && holes_ok && best[i] != usize::MAX {
                    best[j] = best[j].min(best[i] + 1);
                }
            }
        }
        (best[n] != usize::MAX).then_some(best[n])
    }

    fn check(points: &[(u16, u16)], limit: u16, answers: &dyn Fn(u16) -> bool) {
        let requests = plan(points, limit, answers);
        for &(start, count) in &requests {
            assert!(count <= limit, "{requests:?}");
            let in_a_point = |a: u16| points.iter().any(|&(p, w)| a >= p && a < p + w);
            assert!((start..start + count).all(|a| in_a_point(a) || answers(a)), "a hole read: {requests:?}");
        }
        for &(a, w) in points {
            assert!(
                requests.iter().any(|&(s, c)| a >= s && a + w <= s + c),
                "({a}, {w}) split or missing in {requests:?}"
            );
        }
        assert_eq!(Some(requests.len()), optimum(points, limit, answers), "{points:?} limit {limit}");
    }

    #[test]
    fn the_plan_reads_across_mapped_addresses_but_not_holes_within_the_limit() {
        // 0..4 mapped, 4..8 a hole, 8..16 mapped.
        let answers = |a: u16| !(4..8).contains(&a);
        assert_eq!(plan(&[(0, 1), (2, 2), (8, 2), (12, 1)], 4, answers), [(0, 4), (8, 2), (12, 1)]);
        assert_eq!(plan(&[(0, 1), (2, 2), (8, 2), (12, 1)], 8, answers), [(0, 4), (8, 5)]);
        // A 32-bit point is never split: (3, 2) does not join (0, 1) under a limit of 4.
        assert_eq!(plan(&[(0, 1), (3, 2)], 4, |_| true), [(0, 1), (3, 2)]);
    }

    #[test]
    fn the_plan_equals_the_optimum_over_pseudo_random_point_sets() {
        let mut seed: u64 = 0x2545_F491_4F6C_DD1D;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for _ in 0..500 {
            let limit = u16::try_from(next() % 8 + 2).unwrap();
            let holes = next();
            let answers = move |a: u16| a >= 64 || holes >> a & 1 == 1 || a.is_multiple_of(5);
            let mut points = Vec::new();
            let mut at = u16::try_from(next() % 3).unwrap();
            while at < 60 {
                let width = if next() % 4 == 0 { 2 } else { 1 };
                points.push((at, width));
                at += width + u16::try_from(next() % 4).unwrap();
            }
            check(&points, limit, &answers);
        }
    }
}
