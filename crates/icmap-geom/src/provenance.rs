//! Provenance of the instances of a [`GlobalMap`]: which drives observed each instance.
//!
//! A city map is built from many drive maps (see [`crate::merge_map`]); every instance records the
//! set of drives (ids `u32`, chosen by the caller) that observed it. The rest of the provenance is
//! the instance's own bookkeeping: `observations` (how many times it was inserted or merged into,
//! summed over drives by `merge_map`) and `first_frame` / `last_frame` (min / max over drives).
//!
//! The sets live beside the instances (`GlobalMap::drives`: id -> sorted, distinct drive ids; an
//! instance without an entry has no recorded drive), so instances that were never tagged cost
//! nothing. Removing an instance removes its set. This module must not change geometry.

use crate::error::{GeomError, Result};
use crate::store::GlobalMap;

/// The sorted union of two sorted, distinct lists.
pub fn union_sorted(a: &[u32], b: &[u32]) -> Vec<u32> {
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        match a[i].cmp(&b[j]) {
            std::cmp::Ordering::Less => {
                out.push(a[i]);
                i += 1;
            }
            std::cmp::Ordering::Greater => {
                out.push(b[j]);
                j += 1;
            }
            std::cmp::Ordering::Equal => {
                out.push(a[i]);
                i += 1;
                j += 1;
            }
        }
    }
    out.extend_from_slice(&a[i..]);
    out.extend_from_slice(&b[j..]);
    out
}

impl GlobalMap {
    /// The drives (ascending, distinct) that observed instance `id`; empty for an instance
    /// without provenance or an unknown id.
    pub fn drives(&self, id: u64) -> &[u32] {
        self.drives.get(&id).map_or(&[], |d| d)
    }

    /// Records that drive `drive` observed every instance now in the map.
    pub fn tag_drive(&mut self, drive: u32) {
        let ids: Vec<u64> = self.instances_iter().map(|i| i.id).collect();
        self.tag_drive_of(drive, &ids)
            .expect("every id comes from the map itself");
    }

    /// Records that drive `drive` observed the instances `ids` (a map continued drive after
    /// drive tags what each drive inserted or merged). Errors on an unknown id; then nothing
    /// changes.
    pub fn tag_drive_of(&mut self, drive: u32, ids: &[u64]) -> Result<()> {
        if let Some(&bad) = ids.iter().find(|&&id| !self.contains(id)) {
            return Err(GeomError::UnknownId(bad));
        }
        for &id in ids {
            let set = self.drives.entry(id).or_default();
            if let Err(at) = set.binary_search(&drive) {
                let mut v = set.to_vec();
                v.insert(at, drive);
                *set = v.into_boxed_slice();
            }
        }
        Ok(())
    }

    /// Sets the drives of instance `id` (sorted and de-duplicated here; empty clears them).
    /// Errors on an unknown id.
    pub fn set_drives(&mut self, id: u64, drives: &[u32]) -> Result<()> {
        if !self.contains(id) {
            return Err(GeomError::UnknownId(id));
        }
        let mut v = drives.to_vec();
        v.sort_unstable();
        v.dedup();
        if v.is_empty() {
            self.drives.remove(&id);
        } else {
            self.drives.insert(id, v.into_boxed_slice());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::MapConfig;
    use crate::types::{MapClass, Point};

    fn line(y: f64) -> Vec<Point> {
        vec![Point::new(0.0, y), Point::new(5.0, y)]
    }

    #[test]
    fn union_of_sorted_lists() {
        assert_eq!(union_sorted(&[1, 3, 5], &[2, 3, 9]), vec![1, 2, 3, 5, 9]);
        assert_eq!(union_sorted(&[], &[4]), vec![4]);
        assert_eq!(union_sorted(&[4], &[]), vec![4]);
    }

    #[test]
    fn tag_set_and_remove() {
        let mut m = GlobalMap::new(MapConfig::default()).unwrap();
        let a = m.insert(MapClass::Divider, &line(0.0), 0).unwrap();
        assert!(m.drives(a).is_empty());
        m.tag_drive(7);
        m.tag_drive(2);
        m.tag_drive(7);
        let b = m.insert(MapClass::Boundary, &line(9.0), 0).unwrap();
        assert_eq!(m.drives(a), &[2, 7]);
        assert!(
            m.drives(b).is_empty(),
            "tagging covers the instances present at the time"
        );
        m.set_drives(b, &[5, 1, 5]).unwrap();
        assert_eq!(m.drives(b), &[1, 5]);
        assert!(matches!(
            m.set_drives(99, &[1]),
            Err(GeomError::UnknownId(99))
        ));
        m.check_invariants().unwrap();
        m.set_drives(b, &[]).unwrap();
        assert!(m.drives(b).is_empty());
        m.remove(a).unwrap();
        assert!(m.drives(a).is_empty());
        m.check_invariants().unwrap();
        m.tag_drive(u32::MAX);
        assert_eq!(m.drives(b), &[u32::MAX]);
        m.clear();
        m.check_invariants().unwrap();
    }
}
