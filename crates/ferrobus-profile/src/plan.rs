//! The read planner: the fewest read requests that cover a set of points.

/// A run of addresses of one table: `width` registers (or bits) from wire address `start`.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, PartialOrd, Ord)]
pub struct Extent {
    /// The first wire address.
    pub start: u16,
    /// How many addresses (at least 1).
    pub width: u16,
}

impl Extent {
    /// The address just past it.
    pub fn end(self) -> u32 {
        u32::from(self.start) + u32::from(self.width)
    }
}

/// One read request: `count` items from wire address `start`.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct Request {
    /// The first wire address.
    pub start: u16,
    /// Items read.
    pub count: u16,
}

impl Request {
    /// The address just past it.
    pub fn end(self) -> u32 {
        u32::from(self.start) + u32::from(self.count)
    }
}

/// Why no plan covers the points.
#[derive(Clone, Copy, PartialEq, Eq, Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlanError {
    /// A point is wider than one request may be.
    #[error("the value at {start:#06x} takes {width} items, more than the {limit} one request may read")]
    TooWide {
        /// Its address.
        start: u16,
        /// Its width.
        width: u16,
        /// The limit.
        limit: u16,
    },
    /// A limit of zero allows no request.
    #[error("a limit of 0 items per request allows no read")]
    NoLimit,
}

/// The fewest read requests that cover every point of `wanted`, for one table.
///
/// Contract: given the points to read (`wanted`, in any order, duplicates and overlaps
/// allowed: overlapping points are read as one), the addresses the device maps (`mapped`:
/// every entry of the table, wanted or not; the wanted points count as mapped), the spans in
/// which it answers every address (`spans`, `(first, last)` wire addresses, inclusive) and
/// the most items one request may carry (`limit`), return requests, in address order, such
/// that
/// - every wanted point lies whole inside one request (a value is never split);
/// - every request carries at most `limit` items, and starts at the start of a wanted point
///   and ends at the end of one (so it cuts no point, wanted or not, that does not overlap
///   another);
/// - every maximal run of unmapped addresses inside a request lies inside one span (the
///   device answers holes only where the profile says it does);
/// - no plan with these properties has fewer requests.
///
/// The points are grouped in address order, each group as far as the limit and the holes
/// allow (a group's sub-runs are valid whenever the group is, so the greedy grouping is
/// optimal; the tests compare it with a dynamic-programming and an exhaustive optimum).
/// Errors: a point wider than `limit`, or a `limit` of 0 with points to read.
pub fn plan(wanted: &[Extent], mapped: &[Extent], spans: &[(u16, u16)], limit: u16) -> Result<Vec<Request>, PlanError> {
    let points = merge(wanted);
    if points.is_empty() {
        return Ok(Vec::new());
    }
    if limit == 0 {
        return Err(PlanError::NoLimit);
    }
    if let Some(p) = points.iter().find(|p| p.width > limit) {
        return Err(PlanError::TooWide { start: p.start, width: p.width, limit });
    }
    let coverage = Coverage::new(mapped, &points, spans);
    let mut requests = Vec::new();
    let mut iter = points.iter();
    let Some(first) = iter.next() else { return Ok(requests) };
    let (mut start, mut end) = (u32::from(first.start), first.end());
    for p in iter {
        if p.end() - start <= u32::from(limit) && coverage.crossable(end, u32::from(p.start)) {
            end = p.end();
        } else {
            requests.push(request(start, end));
            (start, end) = (u32::from(p.start), p.end());
        }
    }
    requests.push(request(start, end));
    Ok(requests)
}

fn request(start: u32, end: u32) -> Request {
    Request {
        start: u16::try_from(start).unwrap_or(u16::MAX),
        count: u16::try_from(end.saturating_sub(start)).unwrap_or(u16::MAX),
    }
}

/// The points sorted, overlapping ones merged (a merged point is never split either).
pub(crate) fn merge(wanted: &[Extent]) -> Vec<Extent> {
    let mut sorted: Vec<Extent> = wanted.iter().copied().filter(|e| e.width > 0).collect();
    sorted.sort();
    let mut merged: Vec<Extent> = Vec::with_capacity(sorted.len());
    for e in sorted {
        match merged.last_mut() {
            Some(last) if u32::from(e.start) < last.end() => {
                let end = last.end().max(e.end());
                last.width = u16::try_from(end - u32::from(last.start)).unwrap_or(u16::MAX);
            }
            _ => merged.push(e),
        }
    }
    merged
}

/// Which addresses are mapped, and whether a gap between two points may be read across.
pub(crate) struct Coverage<'a> {
    mapped: Vec<bool>,
    spans: &'a [(u16, u16)],
}

impl<'a> Coverage<'a> {
    pub(crate) fn new(mapped: &[Extent], wanted: &[Extent], spans: &'a [(u16, u16)]) -> Self {
        let mut bitmap = vec![false; 0x1_0000];
        for e in mapped.iter().chain(wanted) {
            let (start, end) = (usize::from(e.start), usize::try_from(e.end()).unwrap_or(0x1_0000));
            if let Some(slots) = bitmap.get_mut(start..end.min(0x1_0000)) {
                slots.fill(true);
            }
        }
        Coverage { mapped: bitmap, spans }
    }

    /// Whether addresses `from..to` may be read: each maximal run of unmapped addresses in
    /// them lies inside one span.
    pub(crate) fn crossable(&self, from: u32, to: u32) -> bool {
        let mut a = from;
        while a < to {
            if self.is_mapped(a) {
                a += 1;
                continue;
            }
            let hole_start = a;
            while a < to && !self.is_mapped(a) {
                a += 1;
            }
            let hole_last = a - 1;
            let inside =
                self.spans.iter().any(|&(first, last)| u32::from(first) <= hole_start && hole_last <= u32::from(last));
            if !inside {
                return false;
            }
        }
        true
    }

    fn is_mapped(&self, a: u32) -> bool {
        usize::try_from(a).ok().and_then(|a| self.mapped.get(a)).copied().unwrap_or(false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn e(start: u16, width: u16) -> Extent {
        Extent { start, width }
    }

    #[test]
    fn neighbours_share_a_request_up_to_the_limit_and_a_pair_is_never_split() {
        // Four registers a request: 0-1 (a pair), 2, 3 | 4-5 (a pair) would make five.
        let points = [e(0, 2), e(2, 1), e(3, 1), e(4, 2)];
        let plan = plan(&points, &points, &[], 4).unwrap();
        assert_eq!(plan, [Request { start: 0, count: 4 }, Request { start: 4, count: 2 }]);
    }

    #[test]
    fn a_hole_is_read_across_only_inside_one_span() {
        let points = [e(0x1000, 2), e(0x1003, 1)];
        // 0x1002 is unmapped: without a span the points need two requests.
        assert_eq!(plan(&points, &points, &[], 4).unwrap().len(), 2);
        assert_eq!(plan(&points, &points, &[(0x1000, 0x102F)], 4).unwrap(), [Request { start: 0x1000, count: 4 }]);
        // A hole that runs out of the span, or across two spans that only touch, is not read across.
        assert_eq!(plan(&points, &points, &[(0x0FFF, 0x1001)], 4).unwrap().len(), 2);
        let wide = [e(0x10, 1), e(0x14, 1)];
        assert_eq!(plan(&wide, &wide, &[(0x11, 0x11), (0x12, 0x13)], 8).unwrap().len(), 2);
        // Mapped registers that were not asked for are read across without a span.
        let mapped = [e(0x10, 1), e(0x11, 3), e(0x14, 1)];
        assert_eq!(plan(&wide, &mapped, &[], 8).unwrap(), [Request { start: 0x10, count: 5 }]);
    }

    #[test]
    fn a_point_wider_than_the_limit_is_an_error_naming_it() {
        let err = plan(&[e(0x20, 4)], &[], &[], 2).unwrap_err();
        assert_eq!(err.to_string(), "the value at 0x0020 takes 4 items, more than the 2 one request may read");
        assert_eq!(plan(&[], &[], &[], 0).unwrap(), []);
        assert_eq!(plan(&[e(0, 1)], &[], &[], 0).unwrap_err(), PlanError::NoLimit);
    }

    #[test]
    fn the_last_address_of_the_table_can_be_read() {
        let points = [e(0xFFFE, 1), e(0xFFFF, 1)];
        assert_eq!(plan(&points, &points, &[], 125).unwrap(), [Request { start: 0xFFFE, count: 2 }]);
    }
}
