//! What a traversal hands its touching triangle pairs to: the first one (first contact) or
//! every one (all pairs).
//!
//! One type per mode, shared by plain and cached queries, not one callback that tests the mode
//! at each hit: the traversal is generic over its [`Hits`], so each mode gets its own build of
//! it, in which first contact's stop and all pairs' "go on" are constants. When cached queries
//! used one callback for both modes, their all-pairs traversals that recorded no front took
//! 5-7 % longer than plain ones doing the same work on the near-contact knots
//! (`docs/performance/cpu-core.md`, seventeenth sitting).

/// Takes the touching triangle pairs `(tri_a, tri_b)` a traversal finds.
pub(super) trait Hits {
    /// Takes one pair; true stops the traversal.
    fn hit(&mut self, tri_a: u32, tri_b: u32) -> bool;
}

/// Any closure is a [`Hits`] (tests and one-off traversals).
impl<F: FnMut(u32, u32) -> bool> Hits for F {
    #[inline(always)]
    fn hit(&mut self, tri_a: u32, tri_b: u32) -> bool {
        self(tri_a, tri_b)
    }
}

/// A [`Hits`] that can forget what it took: a cached query's abandoned front walk starts again
/// from the roots and finds its pairs again.
pub(super) trait Restart: Hits {
    /// Forgets every pair taken.
    fn clear(&mut self);
}

/// First contact: keeps the pair found and stops.
pub(super) struct FirstHit<'a>(pub(super) &'a mut Option<(u32, u32)>);

impl Hits for FirstHit<'_> {
    #[inline(always)]
    fn hit(&mut self, tri_a: u32, tri_b: u32) -> bool {
        *self.0 = Some((tri_a, tri_b));
        true
    }
}

impl Restart for FirstHit<'_> {
    fn clear(&mut self) {
        *self.0 = None;
    }
}

/// All pairs: collects every pair and goes on.
pub(super) struct AllHits<'a>(pub(super) &'a mut Vec<(u32, u32)>);

impl Hits for AllHits<'_> {
    #[inline(always)]
    fn hit(&mut self, tri_a: u32, tri_b: u32) -> bool {
        self.0.push((tri_a, tri_b));
        false
    }
}

impl Restart for AllHits<'_> {
    fn clear(&mut self) {
        self.0.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feeds pairs until the collector says stop; returns how many it took.
    fn feed(h: &mut impl Hits, pairs: &[(u32, u32)]) -> usize {
        for (k, &(a, b)) in pairs.iter().enumerate() {
            if h.hit(a, b) {
                return k + 1;
            }
        }
        pairs.len()
    }

    #[test]
    fn first_contact_stops_at_its_pair_and_all_pairs_takes_every_one() {
        let pairs = [(3, 4), (1, 2), (7, 0)];
        let mut found = None;
        assert_eq!(feed(&mut FirstHit(&mut found), &pairs), 1);
        assert_eq!(found, Some((3, 4)));
        let mut all = Vec::new();
        assert_eq!(feed(&mut AllHits(&mut all), &pairs), 3);
        assert_eq!(all, pairs);
        // A closure is a collector too (tests and one-off traversals).
        let mut seen = 0;
        assert_eq!(
            feed(
                &mut |_, _| {
                    seen += 1;
                    seen == 2
                },
                &pairs
            ),
            2
        );
    }

    #[test]
    fn a_restart_forgets_what_was_taken() {
        let mut found = Some((1, 1));
        FirstHit(&mut found).clear();
        assert_eq!(found, None);
        let mut all = vec![(1, 2), (3, 4)];
        let mut h = AllHits(&mut all);
        h.clear();
        assert!(!h.hit(5, 6));
        assert_eq!(all, [(5, 6)]);
    }
}
