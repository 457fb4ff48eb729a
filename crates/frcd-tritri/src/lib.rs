//! # frcd-tritri
//!
//! Triangle-triangle overlap tests. Triangles are closed sets: touching counts as intersecting.
#![warn(missing_docs)]

pub use frcd_geom::Triangle;

/// Which triangle-triangle test to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum Method {
    /// Zou et al. 2008 (reconstructed, see module docs).
    Zou,
    /// Möller 1997, division-free interval overlap.
    Moller,
    /// Guigue & Devillers 2003, orientation predicates in floating point.
    GuigueDevillers,
    /// Shen, Heng & Tang 2003, signed distances.
    Shen,
    /// Tropp, Tal & Shimshoni 2006, shared determinants.
    Tropp,
    /// Filtered exact predicates: the right answer for every finite f64 input.
    #[default]
    Exact,
}

impl Method {
    /// Every method, in a fixed order.
    pub const ALL: [Method; 6] = [
        Method::Zou,
        Method::Moller,
        Method::GuigueDevillers,
        Method::Shen,
        Method::Tropp,
        Method::Exact,
    ];

    /// A short lowercase name (`"zou"`, `"moller"`, `"guigue_devillers"`, `"shen"`, `"tropp"`, `"exact"`).
    pub fn name(self) -> &'static str {
        match self {
            Method::Zou => "zou",
            Method::Moller => "moller",
            Method::GuigueDevillers => "guigue_devillers",
            Method::Shen => "shen",
            Method::Tropp => "tropp",
            Method::Exact => "exact",
        }
    }
}

/// Runs the chosen test on two triangles.
pub fn intersects(method: Method, a: &Triangle, b: &Triangle) -> bool {
    let _ = (method, a, b);
    todo!("being implemented")
}
