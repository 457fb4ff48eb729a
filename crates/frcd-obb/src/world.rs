//! Many bodies: incremental sweep-and-prune broad phase, cached and parallel narrow phase.

use crate::query::{Collision, Containment, Counters, Mode, PairCache, Request, collide_cached};
use crate::tree::ObbTree;
use frcd_geom::{Aabb, DVec3, Pose};
use std::collections::{HashMap, HashSet};
use std::sync::Arc;

/// A body's handle in a [`World`] (its insertion index).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct BodyId(pub u32);

/// Why a [`World`] call was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum WorldError {
    /// No body has this id.
    #[error("no body {id} (the world has {count})")]
    UnknownBody {
        /// The id given.
        id: u32,
        /// Number of bodies.
        count: usize,
    },
    /// A pose with a non-finite value or a rotation that is not a unit quaternion.
    #[error("invalid pose for body {id}: {pose:?}")]
    InvalidPose {
        /// The body.
        id: u32,
        /// The pose given.
        pose: Pose,
    },
}

/// Options of a [`World`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct WorldOptions {
    /// The pair query run on each candidate pair (default: all pairs, surface mode, exact).
    pub request: Request,
    /// Keep a [`PairCache`] per body pair (temporal coherence).
    pub coherence: bool,
    /// A full re-sort of the broad phase happens when an insertion sort would make more than
    /// `resort_factor · n` swaps (incoherent motion), besides after [`World::teleport`].
    pub resort_factor: u32,
}

impl Default for WorldOptions {
    fn default() -> Self {
        Self {
            request: Request {
                mode: Mode::AllPairs,
                ..Request::default()
            },
            coherence: true,
            resort_factor: 8,
        }
    }
}

/// Two bodies that interfere, with their triangle pairs.
#[derive(Clone, Debug, PartialEq)]
pub struct BodyContact {
    /// The lower body id.
    pub a: BodyId,
    /// The higher body id.
    pub b: BodyId,
    /// Touching triangle pairs `(tri of a, tri of b)`, sorted (empty in first-contact mode).
    pub pairs: Vec<(u32, u32)>,
    /// A touching pair, when there is one.
    pub witness: Option<(u32, u32)>,
    /// Solid mode: containment when no surface pair touches.
    pub contained: Option<Containment>,
}

/// What a [`World::step`] found and how much work it took.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StepReport {
    /// Interfering body pairs, sorted by `(a, b)`; identical for any thread count.
    pub contacts: Vec<BodyContact>,
    /// Body pairs whose world boxes overlap (after static/excluded filtering).
    pub candidates: usize,
    /// Candidate pairs answered from the previous step because neither pose changed.
    pub reused: usize,
    /// Work of the narrow-phase queries run this step.
    pub counters: Counters,
}

struct Body {
    tree: Arc<ObbTree>,
    pose: Pose,
    is_static: bool,
    version: u64,
    aabb: Aabb,
}

struct PairState {
    versions: (u64, u64),
    result: Option<Collision>,
    cache: PairCache,
}

/// Bodies sharing trees through `Arc<ObbTree>`, poses updated per step, and a `step` that
/// returns the interfering pairs.
///
/// The broad phase sorts the bodies' world boxes by `min.x` and sweeps; the sort is an insertion
/// sort on last step's order (near linear under coherent motion), replaced by a full sort after a
/// teleport. Static-static pairs, excluded pairs and pairs whose poses did not change since their
/// last answer are not queried again. The narrow phase runs on rayon's current pool with the
/// default `parallel` feature; the result does not depend on the thread count.
///
/// ```
/// use frcd_obb::{BuildOptions, ObbTree, World, WorldOptions};
/// use frcd_geom::{shapes, DVec3, Pose};
/// use std::sync::Arc;
/// let ball = Arc::new(ObbTree::build(&shapes::icosphere(1.0, 2), &BuildOptions::default()));
/// let mut world = World::new(WorldOptions::default());
/// let a = world.add_body(ball.clone(), Pose::IDENTITY, true).unwrap();
/// let b = world
///     .add_body(ball, Pose::from_translation(DVec3::new(5.0, 0.0, 0.0)), false)
///     .unwrap();
/// assert!(world.step().contacts.is_empty());
/// world.set_pose(b, Pose::from_translation(DVec3::new(1.5, 0.0, 0.0))).unwrap();
/// let report = world.step();
/// assert_eq!((report.contacts[0].a, report.contacts[0].b), (a, b));
/// ```
pub struct World {
    options: WorldOptions,
    bodies: Vec<Body>,
    excluded: HashSet<(u32, u32)>,
    order: Vec<u32>,
    resort: bool,
    pairs: HashMap<(u32, u32), PairState>,
}

/// A conservative world box: the local box mapped by the pose, grown by a relative margin that
/// covers the rounding of the pair queries' relative frames.
fn world_box(tree: &ObbTree, pose: &Pose) -> Aabb {
    let b = tree.aabb().transformed(pose);
    let mag = b.min.abs().max(b.max.abs()).max_element();
    b.inflated(mag * 1e-12 + f64::MIN_POSITIVE)
}

impl World {
    /// An empty world.
    pub fn new(options: WorldOptions) -> Self {
        Self {
            options,
            bodies: Vec::new(),
            excluded: HashSet::new(),
            order: Vec::new(),
            resort: false,
            pairs: HashMap::new(),
        }
    }

    /// Number of bodies.
    pub fn len(&self) -> usize {
        self.bodies.len()
    }

    /// True when there are no bodies.
    pub fn is_empty(&self) -> bool {
        self.bodies.is_empty()
    }

    /// Adds a body; static bodies are never tested against each other. An invalid pose
    /// (non-finite, or a rotation that is not a unit quaternion) is refused.
    pub fn add_body(
        &mut self,
        tree: Arc<ObbTree>,
        pose: Pose,
        is_static: bool,
    ) -> Result<BodyId, WorldError> {
        let id = self.bodies.len() as u32;
        if !pose.is_valid() {
            return Err(WorldError::InvalidPose { id, pose });
        }
        let aabb = world_box(&tree, &pose);
        self.bodies.push(Body {
            tree,
            pose,
            is_static,
            version: 0,
            aabb,
        });
        self.order.push(id);
        self.resort = true;
        Ok(BodyId(id))
    }

    fn body_mut(&mut self, id: BodyId, pose: &Pose) -> Result<&mut Body, WorldError> {
        let count = self.bodies.len();
        if !pose.is_valid() {
            return Err(WorldError::InvalidPose {
                id: id.0,
                pose: *pose,
            });
        }
        self.bodies
            .get_mut(id.0 as usize)
            .ok_or(WorldError::UnknownBody { id: id.0, count })
    }

    /// Moves a body (coherent motion: the broad phase re-sorts incrementally).
    pub fn set_pose(&mut self, id: BodyId, pose: Pose) -> Result<(), WorldError> {
        let body = self.body_mut(id, &pose)?;
        if body.pose != pose {
            body.pose = pose;
            body.version += 1;
            body.aabb = world_box(&body.tree, &pose);
        }
        Ok(())
    }

    /// Moves a body far (incoherent motion): the broad phase re-sorts from scratch and the
    /// body's coherence caches are dropped.
    pub fn teleport(&mut self, id: BodyId, pose: Pose) -> Result<(), WorldError> {
        self.set_pose(id, pose)?;
        self.resort = true;
        self.pairs.retain(|k, _| k.0 != id.0 && k.1 != id.0);
        Ok(())
    }

    /// The pose of a body.
    pub fn pose(&self, id: BodyId) -> Option<Pose> {
        self.bodies.get(id.0 as usize).map(|b| b.pose)
    }

    /// Never test this pair (parts joined by design).
    pub fn exclude_pair(&mut self, a: BodyId, b: BodyId) -> Result<(), WorldError> {
        let count = self.bodies.len();
        for id in [a, b] {
            if id.0 as usize >= count {
                return Err(WorldError::UnknownBody { id: id.0, count });
            }
        }
        self.excluded.insert((a.0.min(b.0), a.0.max(b.0)));
        Ok(())
    }

    /// Sorts `order` by `min.x`: insertion sort under coherence, full sort otherwise.
    fn sort(&mut self) {
        let bodies = &self.bodies;
        let key = |i: u32| bodies[i as usize].aabb.min.x;
        if !self.resort {
            let limit = self.options.resort_factor as usize * self.order.len().max(1);
            let mut swaps = 0usize;
            let o = &mut self.order;
            let mut ok = true;
            'outer: for i in 1..o.len() {
                let mut j = i;
                while j > 0 && key(o[j - 1]).total_cmp(&key(o[j])).is_gt() {
                    o.swap(j - 1, j);
                    j -= 1;
                    swaps += 1;
                    if swaps > limit {
                        ok = false;
                        break 'outer;
                    }
                }
            }
            if ok {
                return;
            }
        }
        self.order
            .sort_by(|&x, &y| key(x).total_cmp(&key(y)).then(x.cmp(&y)));
        self.resort = false;
    }

    /// Body pairs whose world boxes overlap, minus static-static and excluded pairs, sorted.
    fn candidates(&self) -> Vec<(u32, u32)> {
        let mut out = Vec::new();
        for (p, &i) in self.order.iter().enumerate() {
            let bi = &self.bodies[i as usize];
            for &j in &self.order[p + 1..] {
                let bj = &self.bodies[j as usize];
                if bj.aabb.min.x > bi.aabb.max.x {
                    break;
                }
                if !bi.aabb.intersects(&bj.aabb) || (bi.is_static && bj.is_static) {
                    continue;
                }
                let key = (i.min(j), i.max(j));
                if !self.excluded.contains(&key) {
                    out.push(key);
                }
            }
        }
        out.sort_unstable();
        out
    }

    /// Advances one step: broad phase, then the narrow phase on the candidate pairs whose poses
    /// changed since their last answer.
    pub fn step(&mut self) -> StepReport {
        self.sort();
        let cands = self.candidates();
        let mut report = StepReport {
            candidates: cands.len(),
            ..StepReport::default()
        };
        let mut old = std::mem::take(&mut self.pairs);
        let mut work: Vec<((u32, u32), PairState)> = cands
            .iter()
            .map(|&k| {
                let st = old.remove(&k).unwrap_or(PairState {
                    versions: (u64::MAX, u64::MAX),
                    result: None,
                    cache: PairCache::new(),
                });
                (k, st)
            })
            .collect();
        drop(old);
        let bodies = &self.bodies;
        let options = self.options;
        let run = |(k, st): &mut ((u32, u32), PairState)| -> bool {
            let (a, b) = (&bodies[k.0 as usize], &bodies[k.1 as usize]);
            let versions = (a.version, b.version);
            if st.result.is_some() && st.versions == versions {
                return true;
            }
            if !options.coherence {
                st.cache.clear();
            }
            let c = collide_cached(
                &a.tree,
                &a.pose,
                &b.tree,
                &b.pose,
                &options.request,
                &mut st.cache,
            );
            st.versions = versions;
            st.result = Some(c);
            false
        };
        #[cfg(feature = "parallel")]
        let reused: Vec<bool> = {
            use rayon::prelude::*;
            work.par_iter_mut().map(run).collect()
        };
        #[cfg(not(feature = "parallel"))]
        let reused: Vec<bool> = work.iter_mut().map(run).collect();
        for ((k, st), reused) in work.into_iter().zip(reused) {
            let c = st.result.as_ref().expect("answered above");
            if reused {
                report.reused += 1;
            } else {
                report.counters += c.counters;
            }
            if c.collide {
                report.contacts.push(BodyContact {
                    a: BodyId(k.0),
                    b: BodyId(k.1),
                    pairs: c.pairs.clone(),
                    witness: c.witness,
                    contained: c.contained,
                });
            }
            self.pairs.insert(k, st);
        }
        report
    }

    /// World box of a body (conservative).
    pub fn body_aabb(&self, id: BodyId) -> Option<Aabb> {
        self.bodies.get(id.0 as usize).map(|b| b.aabb)
    }

    /// Centre of a body's world box (convenience for scene generators).
    pub fn body_center(&self, id: BodyId) -> Option<DVec3> {
        self.body_aabb(id).map(|b| b.center())
    }
}
