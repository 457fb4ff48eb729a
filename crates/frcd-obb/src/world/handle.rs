//! Generational body handles.

use std::sync::atomic::{AtomicU32, Ordering};

/// A body's handle in a [`super::World`]: slot index, generation and the world's serial.
///
/// Handles are made only by [`super::World::add_body`] (the fields are private): a handle kept
/// after [`super::World::remove_body`] is refused even when its slot holds a new body, and a
/// handle of another world is refused too. Ordered by slot index first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct BodyId {
    index: u32,
    generation: u32,
    world: u32,
}

impl BodyId {
    pub(super) fn new(index: u32, generation: u32, world: u32) -> Self {
        Self {
            index,
            generation,
            world,
        }
    }

    /// The slot index (dense: suitable for indexing the caller's own per-body arrays while the
    /// body lives; reused, with a new generation, after the body is removed).
    pub fn index(self) -> u32 {
        self.index
    }

    /// How many bodies held this slot before this one.
    pub fn generation(self) -> u32 {
        self.generation
    }

    pub(super) fn world(self) -> u32 {
        self.world
    }
}

impl std::fmt::Display for BodyId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "body {} (generation {})", self.index, self.generation)
    }
}

static SERIAL: AtomicU32 = AtomicU32::new(1);

/// A serial for a new world (wraps after 2^32 worlds; handles are then told apart by slot and
/// generation only).
pub(super) fn next_world_serial() -> u32 {
    SERIAL.fetch_add(1, Ordering::Relaxed)
}
