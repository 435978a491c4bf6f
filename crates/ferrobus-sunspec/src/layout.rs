//! Where each point of a model found on a device lies: the definition laid over the model's
//! length, with repeating groups counted (by their fixed count, by filling the length, or by
//! the `count` point the device gave) and scale factors tied to the points that name them.
//!
//! Offsets are in registers from the model's `ID` register. A point's name is its path from
//! the model: `W` in the top group, `module2.DCW` in the second instance of the repeating
//! group `module` (instances count from 1), `crv1.pt3.V` for groups in groups.

use crate::def::{Count, GroupDef, ModelDef, PointDef, ScaleFactor};

/// One point of a model, placed.
#[derive(Clone, Debug, PartialEq)]
pub struct Placed<'d> {
    /// Its path in the model: `W`, `module2.DCW`.
    pub name: String,
    /// Registers from the model's `ID` register.
    pub offset: u32,
    /// Its definition.
    pub def: &'d PointDef,
    /// Its scale factor: the offset of the `sunssf` point it names, or a fixed power of ten.
    pub sf: Option<SfAt>,
}

/// Where a placed point's scale factor is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SfAt {
    /// The `sunssf` point at this offset.
    Offset(u32),
    /// A fixed power of ten.
    Fixed(i8),
}

/// The points of a model, placed as far as the registers read so far tell.
#[derive(Clone, Debug, PartialEq)]
pub struct Layout<'d> {
    /// The points in register order.
    pub points: Vec<Placed<'d>>,
    /// False when a repeating group's count is a point not yet read (or a group does not fit
    /// the length): the points stop before it.
    pub complete: bool,
    /// Registers the placed points take, from the `ID` register.
    pub end: u32,
    /// Why the layout is not the model's length, if it is not (what was seen).
    pub mismatch: Option<String>,
}

/// Lays `model` over a model of `length` registers after its header; `data` holds the
/// registers read so far from the `ID` register on (counts are read from it).
pub fn layout<'d>(model: &'d ModelDef, length: u16, data: &[u16]) -> Layout<'d> {
    let total = u32::from(length) + 2;
    let mut state = State { points: Vec::new(), offset: 0, total, data, stopped: false, mismatch: None };
    let mut scope = Vec::new();
    state.group(&model.group, "", &mut scope);
    let end = state.offset;
    if !state.stopped && state.mismatch.is_none() && end != total {
        state.mismatch = Some(format!(
            "the definition takes {} registers after the header, the device says L = {length}",
            end.saturating_sub(2)
        ));
    }
    Layout { points: state.points, complete: !state.stopped, end, mismatch: state.mismatch }
}

struct State<'d, 'a> {
    points: Vec<Placed<'d>>,
    offset: u32,
    total: u32,
    data: &'a [u16],
    stopped: bool,
    mismatch: Option<String>,
}

/// The offsets of the points of each enclosing group instance, innermost last.
type Scope<'d> = Vec<Vec<(&'d str, u32)>>;

impl<'d> State<'d, '_> {
    fn group(&mut self, group: &'d GroupDef, prefix: &str, scope: &mut Scope<'d>) {
        let first = self.points.len();
        let mut mine = Vec::new();
        for p in &group.points {
            mine.push((p.name.as_str(), self.offset));
            self.points.push(Placed { name: format!("{prefix}{}", p.name), offset: self.offset, def: p, sf: None });
            self.offset += u32::from(p.size);
        }
        scope.push(mine);
        for placed in &mut self.points[first..] {
            placed.sf = match &placed.def.sf {
                None => None,
                Some(ScaleFactor::Fixed(n)) => Some(SfAt::Fixed(*n)),
                Some(ScaleFactor::Point(name)) => find(scope, name).map(SfAt::Offset),
            };
        }
        for sub in &group.groups {
            if self.stopped || self.mismatch.is_some() {
                break;
            }
            let count = match &sub.count {
                Count::One => 1,
                Count::Fixed(n) => u32::from(*n),
                Count::Point(name) => {
                    let at = find(scope, name);
                    let Some(n) = at.and_then(|at| usize::try_from(at).ok()).and_then(|at| self.data.get(at)) else {
                        self.stopped = true;
                        break;
                    };
                    u32::from(*n)
                }
                Count::Fill => {
                    let once = sub.registers_once();
                    let left = self.total.saturating_sub(self.offset);
                    if once == 0 || !left.is_multiple_of(once) {
                        self.mismatch = Some(format!(
                            "{left} registers are left for the repeating group {}, not a whole number of its {once}",
                            sub.name
                        ));
                        break;
                    }
                    left / once
                }
            };
            for i in 1..=count {
                if self.offset >= self.total {
                    self.mismatch = Some(format!(
                        "group {} instance {i} of {count} starts at register {} of the model, past its length {}",
                        sub.name,
                        self.offset,
                        self.total.saturating_sub(2)
                    ));
                    break;
                }
                let name = if sub.count == Count::One {
                    format!("{prefix}{}.", sub.name)
                } else {
                    format!("{prefix}{}{i}.", sub.name)
                };
                self.group(sub, &name, scope);
                if self.stopped || self.mismatch.is_some() {
                    break;
                }
            }
        }
        scope.pop();
    }
}

fn find(scope: &Scope<'_>, name: &str) -> Option<u32> {
    scope.iter().rev().find_map(|g| g.iter().find(|(n, _)| *n == name).map(|(_, at)| *at))
}
