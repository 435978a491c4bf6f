//! The read planner against two independent optima: a dynamic program over the points in
//! address order (for the built-in profiles and large random sets), and an exhaustive search
//! over every possible request (for small random sets), and every plan checked for validity.

use std::collections::{HashSet, VecDeque};

use ferrobus_profile::{BUILTIN, Extent, Profile, Request, Table, plan};
use proptest::prelude::*;

/// Whether `requests` is a valid plan for `wanted`: each point whole inside one request, each
/// request within `limit`, every hole inside one span.
fn valid(
    requests: &[Request],
    wanted: &[Extent],
    mapped: &[Extent],
    spans: &[(u16, u16)],
    limit: u16,
) -> Result<(), String> {
    for p in wanted {
        if !requests.iter().any(|r| r.start <= p.start && p.end() <= r.end()) {
            return Err(format!("{p:?} is not whole inside one request of {requests:?}"));
        }
    }
    for r in requests {
        if r.count == 0 || r.count > limit {
            return Err(format!("{r:?} is over the limit {limit}"));
        }
        if let Some(hole) =
            holes(r.start.into(), r.end(), wanted, mapped).into_iter().find(|&(a, b)| !in_one_span(a, b, spans))
        {
            return Err(format!("{r:?} reads the hole {hole:?} outside one span"));
        }
    }
    Ok(())
}

fn is_mapped(a: u32, wanted: &[Extent], mapped: &[Extent]) -> bool {
    let inside = |e: &Extent| u32::from(e.start) <= a && a < e.end();
    wanted.iter().any(inside) || mapped.iter().any(inside)
}

/// The maximal runs `(first, last)` of unmapped addresses in `from..to`.
fn holes(from: u32, to: u32, wanted: &[Extent], mapped: &[Extent]) -> Vec<(u32, u32)> {
    let mut out: Vec<(u32, u32)> = Vec::new();
    for a in from..to {
        if is_mapped(a, wanted, mapped) {
            continue;
        }
        match out.last_mut() {
            Some(last) if last.1 + 1 == a => last.1 = a,
            _ => out.push((a, a)),
        }
    }
    out
}

fn in_one_span(first: u32, last: u32, spans: &[(u16, u16)]) -> bool {
    spans.iter().any(|&(a, b)| u32::from(a) <= first && last <= u32::from(b))
}

/// The points, sorted, overlapping ones merged (as the planner reads them).
fn merged(wanted: &[Extent]) -> Vec<Extent> {
    let mut sorted = wanted.to_vec();
    sorted.sort();
    let mut out: Vec<Extent> = Vec::new();
    for e in sorted {
        match out.last_mut() {
            Some(last) if u32::from(e.start) < last.end() => {
                let end = last.end().max(e.end());
                last.width = u16::try_from(end - u32::from(last.start)).unwrap();
            }
            _ => out.push(e),
        }
    }
    out
}

/// The optimum by dynamic programming: best[j] = the fewest requests for the first j points,
/// over every last group i..j that one request can read.
fn dp_optimum(wanted: &[Extent], mapped: &[Extent], spans: &[(u16, u16)], limit: u16) -> Option<usize> {
    let points = merged(wanted);
    let mut best: Vec<Option<usize>> = vec![None; points.len() + 1];
    best[0] = Some(0);
    for j in 1..=points.len() {
        // Groups that end at point j - 1, longest last; none longer than the limit fits.
        for i in (0..j).rev() {
            let (start, end) = (u32::from(points[i].start), points[j - 1].end());
            if end - start > u32::from(limit) {
                break;
            }
            let crossable = holes(start, end, &points, mapped).into_iter().all(|(a, b)| in_one_span(a, b, spans));
            if let (true, Some(before)) = (crossable, best[i]) {
                best[j] = Some(best[j].map_or(before + 1, |b: usize| b.min(before + 1)));
            }
        }
    }
    best[points.len()]
}

/// The optimum by exhaustive search: breadth-first over sets of covered points, trying every
/// request [s, e) in the address range that is valid on its own.
fn exhaustive_optimum(
    wanted: &[Extent],
    mapped: &[Extent],
    spans: &[(u16, u16)],
    limit: u16,
    top: u32,
) -> Option<usize> {
    let points = merged(wanted);
    let n = points.len();
    let full: u32 = (1u32 << n) - 1;
    let mut moves: Vec<u32> = Vec::new();
    for s in 0..top {
        for e in s + 1..=top.min(s + u32::from(limit)) {
            let r = Request { start: u16::try_from(s).unwrap(), count: u16::try_from(e - s).unwrap() };
            // A request may not cut a point.
            if points
                .iter()
                .any(|p| u32::from(p.start) < e && s < p.end() && !(s <= u32::from(p.start) && p.end() <= e))
            {
                continue;
            }
            if holes(s, e, &points, mapped).into_iter().any(|(a, b)| !in_one_span(a, b, spans)) {
                continue;
            }
            let covered = points
                .iter()
                .enumerate()
                .filter(|(_, p)| r.start <= p.start && p.end() <= r.end())
                .fold(0u32, |m, (i, _)| m | (1 << i));
            if covered != 0 {
                moves.push(covered);
            }
        }
    }
    let mut seen = HashSet::from([0u32]);
    let mut queue = VecDeque::from([(0u32, 0usize)]);
    while let Some((set, depth)) = queue.pop_front() {
        if set == full {
            return Some(depth);
        }
        for m in &moves {
            let next = set | m;
            if seen.insert(next) {
                queue.push_back((next, depth + 1));
            }
        }
    }
    None
}

#[test]
fn plans_for_every_table_of_every_builtin_profile_are_valid_and_optimal() {
    for (name, _) in BUILTIN {
        let profile = Profile::builtin(name).unwrap();
        for table in Table::ALL {
            let wanted: Vec<Extent> = profile
                .points()
                .iter()
                .filter(|p| p.table == table && p.readable())
                .map(|p| Extent { start: p.address, width: p.width })
                .collect();
            let mapped = profile.mapped(table);
            let spans = profile.spans(table);
            let limit = profile.read_limit(table);
            let requests = plan(&wanted, &mapped, &spans, limit).unwrap();
            valid(&requests, &wanted, &mapped, &spans, limit).unwrap_or_else(|e| panic!("{name} {table:?}: {e}"));
            assert_eq!(Some(requests.len()), dp_optimum(&wanted, &mapped, &spans, limit), "{name} {table:?}");
            // Every other point, and every third: still optimal.
            for step in [2, 3] {
                let some: Vec<Extent> = wanted.iter().copied().step_by(step).collect();
                let requests = plan(&some, &mapped, &spans, limit).unwrap();
                valid(&requests, &some, &mapped, &spans, limit).unwrap_or_else(|e| panic!("{name} {table:?}: {e}"));
                assert_eq!(Some(requests.len()), dp_optimum(&some, &mapped, &spans, limit), "{name} {table:?} /{step}");
            }
        }
    }
}

/// Wanted points, other mapped items, spans, the limit.
type Scenario = (Vec<Extent>, Vec<Extent>, Vec<(u16, u16)>, u16);

/// A random map of up to `top` addresses: non-overlapping items of width 1, 2 or 4, some of
/// them wanted, some spans.
fn scenario(top: u16, max_items: usize) -> impl Strategy<Value = Scenario> {
    (
        proptest::collection::vec((0..top, prop_oneof![Just(1u16), Just(2), Just(4)], any::<bool>()), 1..max_items),
        proptest::collection::vec((0..top, 0..top / 2), 0..3),
        1u16..10,
    )
        .prop_map(move |(items, spans, limit)| {
            let mut taken = vec![false; usize::from(top) + 4];
            let (mut wanted, mut mapped) = (Vec::new(), Vec::new());
            for (start, width, want) in items {
                let range = usize::from(start)..usize::from(start) + usize::from(width);
                if range.end > usize::from(top) || taken[range.clone()].iter().any(|t| *t) {
                    continue;
                }
                taken[range].fill(true);
                let e = Extent { start, width };
                if want { wanted.push(e) } else { mapped.push(e) }
            }
            let spans = spans.into_iter().map(|(a, len)| (a, a.saturating_add(len).min(top - 1))).collect();
            (wanted, mapped, spans, limit)
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn random_small_maps_are_planned_as_well_as_an_exhaustive_search_can((wanted, mapped, spans, limit) in scenario(24, 12)) {
        let wanted: Vec<Extent> = wanted.into_iter().take(10).collect();
        match plan(&wanted, &mapped, &spans, limit) {
            Ok(requests) => {
                prop_assert_eq!(valid(&requests, &wanted, &mapped, &spans, limit), Ok(()));
                prop_assert_eq!(Some(requests.len()), exhaustive_optimum(&wanted, &mapped, &spans, limit, 24));
                prop_assert_eq!(Some(requests.len()), dp_optimum(&wanted, &mapped, &spans, limit));
            }
            Err(_) => prop_assert!(wanted.iter().any(|p| p.width > limit)),
        }
    }

    #[test]
    fn random_large_maps_are_planned_as_well_as_the_dynamic_program((wanted, mapped, spans, limit) in scenario(400, 120)) {
        if let Ok(requests) = plan(&wanted, &mapped, &spans, limit) {
            prop_assert_eq!(valid(&requests, &wanted, &mapped, &spans, limit), Ok(()));
            prop_assert_eq!(Some(requests.len()), dp_optimum(&wanted, &mapped, &spans, limit));
        } else {
            prop_assert!(wanted.iter().any(|p| p.width > limit));
        }
    }
}
