//! Basic types: points, map classes, 2-D poses and oriented patches.

use crate::error::{GeomError, Result};
use nalgebra::{Isometry2, Point2, Vector2};
use parry2d_f64::bounding_volume::Aabb;

/// A point in metres (world or ego frame, as the function says).
pub type Point = Point2<f64>;

/// The engine's coordinate domain: every coordinate (of points and poses) is finite with
/// `|x|, |y| <= MAX_COORD` metres, and half extents and margins of a patch are at most
/// `MAX_COORD`. Every entry point rejects values outside it ([`GeomError::OutOfDomain`],
/// [`GeomError::NonFinite`]) instead of computing overflowed or NaN results.
///
/// 1e7 m (10,000 km) holds any map frame in use: city frames of a few km (Argoverse 2,
/// nuScenes), and UTM eastings / northings (< 1e6 / 1e7 m). Inside it every derived quantity
/// stays far from overflow (squared distances below 1e15 m^2), float64 resolves about 2e-9 m at
/// its edge, and ego-frame offsets of a patch fit float32.
pub const MAX_COORD: f64 = 1e7;

/// Whether `v` lies in the coordinate domain (finite, `|v| <= MAX_COORD`; NaN does not).
#[inline]
pub fn in_domain(v: f64) -> bool {
    v.abs() <= MAX_COORD
}

/// The error for a value `v` of `what` that is not [`in_domain`]: non-finite or out of the domain.
pub fn domain_error(what: &str, v: f64) -> GeomError {
    if v.is_finite() {
        GeomError::OutOfDomain {
            what: what.into(),
            value: v,
        }
    } else {
        GeomError::NonFinite { what: what.into() }
    }
}

/// Map element classes, in StreamMapNet's order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum MapClass {
    /// Pedestrian crossing: a closed polygon.
    PedCrossing = 0,
    /// Lane divider: an open polyline.
    Divider = 1,
    /// Road boundary: an open polyline.
    Boundary = 2,
}

impl MapClass {
    /// All classes in index order.
    pub const ALL: [MapClass; 3] = [MapClass::PedCrossing, MapClass::Divider, MapClass::Boundary];

    /// Whether instances of this class are closed contours (only crossings).
    pub fn is_closed(self) -> bool {
        matches!(self, MapClass::PedCrossing)
    }

    /// How a stored line of this class is kept from folding onto itself: the store merges and
    /// splices lines by the rules that cut the stored line where it comes back beside a new view
    /// ([`crate::splice::Unfold`]). Lane lines within [`crate::splice::LANE_FOLD`] (neighbouring
    /// lanes lie further apart), unbounded; kerbs within [`crate::splice::KERB_FOLD`] (a kerb
    /// around a median island comes back further away), bounded to what lies back on the line
    /// but [`crate::splice::KERB_SLACK`], and may close around a block;
    /// `None` for crossings.
    pub const fn fold(self) -> Option<crate::splice::Fold> {
        use crate::splice::{Fold, KERB_FOLD, KERB_SLACK, LANE_FOLD};
        match self {
            MapClass::PedCrossing => None,
            MapClass::Divider => Some(Fold {
                gap: LANE_FOLD,
                slack: f64::INFINITY,
                loops: false,
            }),
            MapClass::Boundary => Some(Fold {
                gap: KERB_FOLD,
                slack: KERB_SLACK,
                loops: true,
            }),
        }
    }

    /// The class index (0, 1, 2).
    pub fn index(self) -> u8 {
        self as u8
    }

    /// The class name used in files and tables.
    pub fn name(self) -> &'static str {
        match self {
            MapClass::PedCrossing => "ped_crossing",
            MapClass::Divider => "divider",
            MapClass::Boundary => "boundary",
        }
    }
}

impl TryFrom<i64> for MapClass {
    type Error = GeomError;
    fn try_from(v: i64) -> Result<Self> {
        match v {
            0 => Ok(MapClass::PedCrossing),
            1 => Ok(MapClass::Divider),
            2 => Ok(MapClass::Boundary),
            other => Err(GeomError::UnknownClass(other)),
        }
    }
}

/// A 2-D pose ego -> world: position `(x, y)` in metres and heading `yaw` in radians.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose2 {
    pub x: f64,
    pub y: f64,
    pub yaw: f64,
}

impl Pose2 {
    /// A pose; errors if a component is not finite or the position lies outside the coordinate
    /// domain ([`MAX_COORD`]).
    pub fn new(x: f64, y: f64, yaw: f64) -> Result<Self> {
        let pose = Pose2 { x, y, yaw };
        pose.check()?;
        Ok(pose)
    }

    /// Errors unless the pose is one [`Pose2::new`] accepts (its fields are public).
    pub fn check(&self) -> Result<()> {
        if !self.yaw.is_finite() {
            return Err(GeomError::NonFinite {
                what: "pose".into(),
            });
        }
        for v in [self.x, self.y] {
            if !in_domain(v) {
                return Err(domain_error("pose", v));
            }
        }
        Ok(())
    }

    /// Whether the pose is one [`Pose2::new`] accepts (its fields are public).
    pub fn is_valid(&self) -> bool {
        in_domain(self.x) && in_domain(self.y) && self.yaw.is_finite()
    }

    /// The isometry ego -> world.
    pub fn isometry(&self) -> Isometry2<f64> {
        Isometry2::new(Vector2::new(self.x, self.y), self.yaw)
    }

    /// Maps an ego-frame point to the world frame.
    pub fn to_world(&self, p: &Point) -> Point {
        self.isometry() * p
    }

    /// Maps a world-frame point to the ego frame.
    pub fn to_ego(&self, p: &Point) -> Point {
        self.isometry().inverse_transform_point(p)
    }
}

/// An oriented rectangle in the world: centred on `pose`, `half_extents` along the ego x and y axes
/// (already including any margin).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Patch {
    pub pose: Pose2,
    pub half_extents: Vector2<f64>,
}

impl Patch {
    /// The patch of `pose` with half extents `(hx + margin, hy + margin)`. Errors on non-finite
    /// values, on negative resulting extents (a negative `hx`, `hy` or `margin` is rejected), on
    /// a value above [`MAX_COORD`], and on a pose outside the domain.
    pub fn new(pose: Pose2, hx: f64, hy: f64, margin: f64) -> Result<Self> {
        pose.check()?;
        for (name, v) in [
            ("half_extents", hx),
            ("half_extents", hy),
            ("margin", margin),
        ] {
            if !v.is_finite() {
                return Err(GeomError::NonFinite { what: name.into() });
            }
            if v > MAX_COORD {
                return Err(domain_error(name, v));
            }
            if v < 0.0 {
                return Err(GeomError::InvalidParameter {
                    name: if name == "margin" {
                        "margin"
                    } else {
                        "half_extents"
                    },
                    reason: format!("must be >= 0, got {v}"),
                });
            }
        }
        Ok(Patch {
            pose,
            half_extents: Vector2::new(hx + margin, hy + margin),
        })
    }

    /// Whether the patch is one [`Patch::new`] accepts (its fields are public): a valid pose and
    /// half extents in `[0, 2 MAX_COORD]`.
    pub fn is_valid(&self) -> bool {
        let (hx, hy) = (self.half_extents.x, self.half_extents.y);
        self.pose.is_valid()
            && (0.0..=2.0 * MAX_COORD).contains(&hx)
            && (0.0..=2.0 * MAX_COORD).contains(&hy)
    }

    /// Whether a world point lies inside the patch (boundary included).
    pub fn contains(&self, p: &Point) -> bool {
        let e = self.pose.to_ego(p);
        e.x.abs() <= self.half_extents.x && e.y.abs() <= self.half_extents.y
    }

    /// The four corners in the world frame, counter-clockwise.
    pub fn corners(&self) -> [Point; 4] {
        let (hx, hy) = (self.half_extents.x, self.half_extents.y);
        [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)]
            .map(|(x, y)| self.pose.to_world(&Point::new(x, y)))
    }

    /// The world-axis-aligned bounding box of the patch.
    pub fn world_aabb(&self) -> Aabb {
        points_aabb(&self.corners())
    }
}

/// The axis-aligned bounding box of `points` (at least one).
pub(crate) fn points_aabb(points: &[Point]) -> Aabb {
    let mut mins = points[0];
    let mut maxs = points[0];
    for p in &points[1..] {
        mins = mins.inf(p);
        maxs = maxs.sup(p);
    }
    Aabb::new(mins, maxs)
}

/// Checks that the parameter `name` is finite and >= 0 ([`GeomError::InvalidParameter`] if not).
pub(crate) fn check_non_negative(name: &'static str, v: f64) -> Result<()> {
    if !(v.is_finite() && v >= 0.0) {
        return Err(GeomError::InvalidParameter {
            name,
            reason: format!("must be finite and >= 0, got {v}"),
        });
    }
    Ok(())
}

/// Checks that the parameter `name` is finite and > 0 ([`GeomError::InvalidParameter`] if not).
pub(crate) fn check_positive(name: &'static str, v: f64) -> Result<()> {
    if !(v.is_finite() && v > 0.0) {
        return Err(GeomError::InvalidParameter {
            name,
            reason: format!("must be finite and > 0, got {v}"),
        });
    }
    Ok(())
}

/// Checks that `points` has at least `min` points and only coordinates in the domain (finite,
/// `|x|, |y| <= MAX_COORD`); `what` names the geometry in the error message.
pub fn validate_points(points: &[Point], min: usize, what: &str) -> Result<()> {
    if points.len() < min {
        return Err(GeomError::TooFewPoints {
            what: what.into(),
            got: points.len(),
            min,
        });
    }
    if !points_in_domain(points) {
        // The first offending value decides the error (NaN / inf, or finite but too large).
        let bad = points
            .iter()
            .flat_map(|p| [p.x, p.y])
            .find(|&v| !in_domain(v))
            .unwrap_or(f64::NAN);
        return Err(domain_error(what, bad));
    }
    Ok(())
}

/// Whether every coordinate of `points` is [`in_domain`].
#[inline]
pub fn points_in_domain(points: &[Point]) -> bool {
    points.iter().all(|p| in_domain(p.x) && in_domain(p.y))
}
