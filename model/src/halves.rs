//! Work on two cores without giving up bit-identical results: the work is split at a place
//! fixed by the data (half of the readings, half of the columns), never by the machine or by
//! timing, and the two halves' results are combined in a fixed order. Whether the halves then
//! run side by side or one after the other changes the time, not a single bit.

/// Readings from which splitting pays (a thread costs more than it saves below).
pub(crate) const PARALLEL_FROM: usize = 2_000;

/// Runs `a` and `b`, side by side when `parallel` (else one after the other): `(a(), b())`.
pub(crate) fn both<A: Send, B: Send>(
    parallel: bool,
    a: impl FnOnce() -> A + Send,
    b: impl FnOnce() -> B + Send,
) -> (A, B) {
    if !parallel {
        return (a(), b());
    }
    std::thread::scope(|sc| {
        let second = sc.spawn(b);
        (a(), second.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
    })
}

/// How many of the leading items, of lengths `lens` (in order), make the first half of their
/// total: the first item whose start is at or beyond half the total begins the second half.
pub(crate) fn first_half(lens: impl Iterator<Item = usize> + Clone) -> usize {
    let total: usize = lens.clone().sum();
    let mut seen = 0;
    lens.take_while(|&l| {
        let before = seen;
        seen += l;
        2 * before < total
    })
    .count()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_halves_split_at_half_of_the_total() {
        assert_eq!(first_half([3, 3, 3, 3].into_iter()), 2);
        assert_eq!(first_half([10, 1, 1].into_iter()), 1);
        assert_eq!(first_half([1, 1, 10].into_iter()), 3);
        assert_eq!(first_half(std::iter::empty()), 0);
        assert_eq!(both(true, || 1, || 2), both(false, || 1, || 2));
    }
}
