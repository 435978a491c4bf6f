//! What a reload keeps, decided from two configurations alone (no IO): each item of the new
//! one matched to the running one's by what it is (a gateway line by its port, a bridge device
//! by its id), then told unchanged or changed by its settings. The gateway's
//! ([`gateway::reload`](crate::gateway::reload)) and the bridge's plans are made of these.

/// What becomes of one item of the new configuration.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Fate {
    /// The running item `was` (its index there) goes on as it is.
    Unchanged {
        /// Its index among the running items.
        was: usize,
    },
    /// The running item `was` is stopped, and this one started in its place.
    Changed {
        /// Its index among the running items.
        was: usize,
    },
    /// A new item.
    Added,
}

/// Each of `new`'s items' fate among `old`'s: matched by `same_item`, unchanged when
/// `same_settings` too.
pub fn fates<T>(
    old: &[T],
    new: &[T],
    same_item: impl Fn(&T, &T) -> bool,
    same_settings: impl Fn(&T, &T) -> bool,
) -> Vec<Fate> {
    new.iter()
        .map(|item| match old.iter().position(|o| same_item(o, item)) {
            Some(was) if old.get(was).is_some_and(|o| same_settings(o, item)) => Fate::Unchanged { was },
            Some(was) => Fate::Changed { was },
            None => Fate::Added,
        })
        .collect()
}

/// The indices of `old`'s items that `new` does not have, matched by `same_item`.
pub fn removed<T>(old: &[T], new: &[T], same_item: impl Fn(&T, &T) -> bool) -> Vec<usize> {
    (0..old.len()).filter(|&i| old.get(i).is_some_and(|o| !new.iter().any(|n| same_item(o, n)))).collect()
}

/// `1 line added, 1 changed, 0 removed, 3 unchanged`: `fates` and `removed` counted, `what`
/// the items' name.
pub fn tally(what: &str, fates: &[Fate], removed: usize) -> String {
    let added = fates.iter().filter(|f| **f == Fate::Added).count();
    let changed = fates.iter().filter(|f| matches!(f, Fate::Changed { .. })).count();
    let unchanged = fates.len().saturating_sub(added).saturating_sub(changed);
    let plural = if added == 1 { "" } else { "s" };
    format!("{added} {what}{plural} added, {changed} changed, {removed} removed, {unchanged} unchanged")
}

#[cfg(test)]
mod tests {
    use super::{Fate, fates, removed, tally};

    #[test]
    fn items_are_matched_by_what_they_are_and_told_apart_by_their_settings() {
        // (name, setting)
        let old = [("a", 1), ("b", 2), ("c", 3)];
        let new = [("c", 3), ("a", 9), ("d", 4)];
        let name = |x: &(&str, i32), y: &(&str, i32)| x.0 == y.0;
        let fates = fates(&old, &new, name, |x, y| x == y);
        assert_eq!(fates, [Fate::Unchanged { was: 2 }, Fate::Changed { was: 0 }, Fate::Added]);
        assert_eq!(removed(&old, &new, name), [1]);
        assert_eq!(tally("line", &fates, 1), "1 line added, 1 changed, 1 removed, 1 unchanged");
        assert_eq!(tally("device", &[], 0), "0 devices added, 0 changed, 0 removed, 0 unchanged");
    }
}
