//! A fixed-size first-in first-out queue: no allocation, never panics.

/// Up to `N` values, oldest first.
#[derive(Clone, Copy, Debug)]
pub(super) struct Ring<T, const N: usize> {
    slots: [Option<T>; N],
    head: usize,
    len: usize,
}

impl<T: Copy, const N: usize> Ring<T, N> {
    pub(super) const fn new() -> Self {
        Ring { slots: [None; N], head: 0, len: 0 }
    }

    pub(super) const fn len(&self) -> usize {
        self.len
    }

    pub(super) const fn is_full(&self) -> bool {
        self.len >= N
    }

    /// Appends `value`, or gives it back when the queue is full.
    pub(super) fn push(&mut self, value: T) -> Result<(), T> {
        if self.is_full() {
            return Err(value);
        }
        let slot = self.head.saturating_add(self.len).checked_rem(N).and_then(|i| self.slots.get_mut(i));
        let Some(slot) = slot else { return Err(value) };
        *slot = Some(value);
        self.len = self.len.saturating_add(1);
        Ok(())
    }

    /// Takes the oldest value.
    pub(super) fn pop(&mut self) -> Option<T> {
        if self.len == 0 {
            return None;
        }
        let value = self.slots.get_mut(self.head).and_then(Option::take);
        self.head = self.head.saturating_add(1).checked_rem(N).unwrap_or(0);
        self.len = self.len.saturating_sub(1);
        value
    }
}

#[cfg(test)]
mod tests {
    use super::Ring;

    #[test]
    fn a_ring_keeps_order_refuses_past_its_size_and_wraps() {
        let mut ring: Ring<u8, 3> = Ring::new();
        assert_eq!((ring.push(1), ring.push(2), ring.push(3), ring.push(4)), (Ok(()), Ok(()), Ok(()), Err(4)));
        assert_eq!(ring.pop(), Some(1));
        assert_eq!(ring.push(5), Ok(()));
        assert_eq!([ring.pop(), ring.pop(), ring.pop(), ring.pop()], [Some(2), Some(3), Some(5), None]);
        let mut empty: Ring<u8, 0> = Ring::new();
        assert_eq!((empty.push(1), empty.pop()), (Err(1), None));
    }
}
