//! One stable least-significant-digit radix sort on `u64` keys, for the two long lists the
//! crate sorts on a hot path: a query's triangle pairs (`query.rs`) and the swept boxes of the
//! `World`'s broad-phase rebuild (`world/broad.rs`).

/// Sorts `items` stably by `key`, a digit of `log2(buckets.len())` bits a pass (`buckets`,
/// the caller's count table, a power of two of at most 2^16 entries: 256 for the short
/// lists of a query, more for long ones), skipping every pass whose digit is the same in all
/// keys. `spare` is scratch (any length on entry; its contents are overwritten). Lists longer
/// than `u32::MAX` (beyond the counts' range) take the standard library's stable sort.
#[inline]
pub(crate) fn sort_by_u64_key<T: Copy>(
    items: &mut Vec<T>,
    spare: &mut Vec<T>,
    buckets: &mut [u32],
    key: impl Fn(&T) -> u64,
) {
    assert!(
        buckets.len().is_power_of_two() && (2..=1 << 16).contains(&buckets.len()),
        "a power of two from 2 to 65,536 buckets"
    );
    let Some(&first) = items.first() else {
        return;
    };
    if items.len() > u32::MAX as usize {
        items.sort_by_key(key);
        return;
    }
    let bits = buckets.len().trailing_zeros() as usize;
    let mask = buckets.len() as u64 - 1;
    // Bits that differ between some two keys: a digit without any is the same everywhere.
    let (or, and) = items
        .iter()
        .fold((0u64, u64::MAX), |(o, a), t| (o | key(t), a & key(t)));
    spare.clear();
    spare.resize(items.len(), first);
    for shift in (0..64).step_by(bits) {
        if ((or ^ and) >> shift) & mask == 0 {
            continue;
        }
        buckets.fill(0);
        for t in items.iter() {
            buckets[((key(t) >> shift) & mask) as usize] += 1;
        }
        let mut sum = 0;
        for s in buckets.iter_mut() {
            (*s, sum) = (sum, sum + *s);
        }
        for &t in items.iter() {
            let d = ((key(&t) >> shift) & mask) as usize;
            spare[buckets[d] as usize] = t;
            buckets[d] += 1;
        }
        std::mem::swap(items, spare);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The comparison sort's order, stable (equal keys keep their order), at 8 and 11 bits a
    /// pass, on keys that differ in few bits, in every bit, or not at all.
    #[test]
    fn equals_a_stable_comparison_sort() {
        let mut next = crate::test_rng::xorshift(0x5EED);
        let lists: Vec<Vec<(u64, u32)>> = vec![
            vec![],
            vec![(7, 0)],
            (0..3000).map(|i| (next(), i)).collect(),
            (0..3000).map(|i| ((next() % 5) << 40, i)).collect(),
            (0..300).map(|i| (42, i)).collect(),
        ];
        for list in lists {
            let mut want = list.clone();
            want.sort_by_key(|e| e.0);
            let (mut a, mut b) = (list.clone(), Vec::new());
            sort_by_u64_key(&mut a, &mut b, &mut [0; 256], |e| e.0);
            assert_eq!(a, want);
            let mut c = list.clone();
            sort_by_u64_key(&mut c, &mut b, &mut [0; 2048], |e| e.0);
            assert_eq!(c, want);
        }
    }
}
