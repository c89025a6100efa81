//! Reading the map by place: instances whose boxes meet a box, the candidates of a patch, and
//! the patch sample (clipped to the patch and sampled evenly in the ego frame).

use super::{GlobalMap, Instance, PatchSample, MAX_PATCH_POINTS};
use crate::clip::{clip_polygon, clip_polyline, sample_pieces};
use crate::error::{GeomError, Result};
use crate::types::Patch;
use parry2d_f64::bounding_volume::Aabb;

impl GlobalMap {
    /// Ids (ascending) of the instances whose bounding box intersects `aabb` (no exact test).
    pub fn query_aabb(&self, aabb: &Aabb) -> Vec<u64> {
        let mut ids: Vec<u64> = self
            .index
            .query(aabb)
            .into_iter()
            .filter_map(|s| self.slots.get(s as usize)?.as_ref().map(|i| i.id))
            .collect();
        ids.sort_unstable();
        ids
    }

    /// Candidates of the patch's world box, as instances sorted by id.
    fn candidates(&self, patch: &Patch) -> Vec<&Instance> {
        let mut v: Vec<&Instance> = self
            .index
            .query(&patch.world_aabb())
            .into_iter()
            .filter_map(|s| self.slots.get(s as usize)?.as_ref())
            .collect();
        v.sort_unstable_by_key(|i| i.id);
        v
    }

    /// Ids (ascending) of the instances whose geometry intersects the patch (exact test after the
    /// bounding-box query). A patch that [`Patch::new`] would refuse (non-finite, negative or
    /// outside the coordinate domain) intersects nothing.
    pub fn query(&self, patch: &Patch) -> Vec<u64> {
        if !patch.is_valid() {
            return Vec::new();
        }
        self.candidates(patch)
            .into_iter()
            .filter(|inst| {
                if inst.closed {
                    !clip_polygon(&inst.points, patch).is_empty()
                } else {
                    !clip_polyline(&inst.points, patch).is_empty()
                }
            })
            .map(|inst| inst.id)
            .collect()
    }

    /// Every instance in the patch clipped to it and sampled evenly to `n_points` in the ego frame.
    ///
    /// Instances whose clipped geometry has zero length are skipped. Errors on a patch that
    /// [`Patch::new`] would refuse (non-finite, negative, outside the domain), on `n_points < 2`
    /// or `> MAX_PATCH_POINTS`, and on `n_points < 3` when a closed crossing is to be sampled.
    pub fn sample_patch(&self, patch: &Patch, n_points: usize) -> Result<PatchSample> {
        if !patch.is_valid() {
            patch.pose.check()?;
            return Err(GeomError::InvalidParameter {
                name: "half_extents",
                reason: format!(
                    "the patch's half extents must be finite and in [0, 2e7] m, got {:?}",
                    patch.half_extents
                ),
            });
        }
        if !(2..=MAX_PATCH_POINTS).contains(&n_points) {
            return Err(GeomError::InvalidParameter {
                name: "n_points",
                reason: format!("must be in 2..={MAX_PATCH_POINTS}, got {n_points}"),
            });
        }
        let iso_inv = patch.pose.isometry().inverse();
        let mut out = PatchSample {
            ids: Vec::new(),
            classes: Vec::new(),
            points: Vec::new(),
            mask: Vec::new(),
            n_points,
        };
        for inst in self.candidates(patch) {
            let sampled = if inst.closed {
                let ring = clip_polygon(&inst.points, patch);
                if ring.is_empty() {
                    continue;
                }
                if n_points < 3 {
                    return Err(GeomError::InvalidParameter {
                        name: "n_points",
                        reason: format!(
                            "a closed crossing needs at least 3 points, got {n_points}"
                        ),
                    });
                }
                sample_pieces(&[ring], true, n_points)?
            } else {
                let pieces = clip_polyline(&inst.points, patch);
                if pieces.is_empty() {
                    continue;
                }
                sample_pieces(&pieces, false, n_points)?
            };
            let Some((pts, mask)) = sampled else { continue };
            if pts.len() != n_points || mask.len() != n_points {
                return Err(GeomError::InvalidParameter {
                    name: "n_points",
                    reason: format!(
                        "sampling returned {} points for {n_points} requested",
                        pts.len()
                    ),
                });
            }
            out.ids.push(inst.id);
            out.classes.push(inst.class);
            out.points.extend(pts.iter().map(|p| iso_inv * p));
            out.mask.extend_from_slice(&mask);
        }
        Ok(out)
    }
}
