//! Hull points carved once per job (issue 38, item 5). The lost-track merge carves visual-hull
//! points for the objects the sparse points missed (their appearance counts in the merge), and
//! the trainer's initial model carves them again from the merged masks. An object's carve reads
//! its own pixels in every view, the ids around each sample's position in the other views
//! ([`super::view_masks::ViewMasks::id_near`]), the cameras, the points' depths and the fill;
//! a merge rewrites only the merged ids' pixels. So an object that was not merged, and whose
//! pixels nowhere touch a pixel of an id merged away (`id_near` reads 2 x 2 pixels, which a
//! merge could tip), carves the same points from the merged masks: those are kept and reused,
//! the rest carved again. The trainer's model is the same as carving everything twice
//! (`track_merge::tests::the_trainers_model_reuses_the_merges_hull_points`).

use std::collections::hash_map::DefaultHasher;
use std::collections::{BTreeMap, BTreeSet};
use std::hash::{Hash, Hasher};

use glam::Vec3;

use super::hull_points::HullFill;
use super::track_merge::IdRemap;
use super::view_masks::ViewMaskSet;
use segsplat_engine::GaussianModel;
use segsplat_scene::Level;
use segsplat_scene::id_runs::id_runs;

/// Points carved per object, and what they were carved from besides the masks.
#[derive(Debug, Clone, Default)]
pub struct CarvedHulls {
    /// Per level, each carved object's points.
    objects: [BTreeMap<u32, Vec<Vec3>>; 3],
    carved_from: Option<CarvedFrom>,
    /// Objects whose points were reused instead of carved (for logs and tests).
    reused: usize,
}

/// The inputs of a carve other than the masks' ids: when they differ nothing is reused.
#[derive(Debug, Clone, PartialEq)]
struct CarvedFrom {
    /// A hash of the points' positions (they give each view's depth range).
    positions: u64,
    /// The views' frames, in order.
    frames: Vec<usize>,
    fill: HullFill,
}

impl CarvedHulls {
    /// Objects whose points are kept.
    pub fn len(&self) -> usize {
        self.objects.iter().map(BTreeMap::len).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Objects whose points were reused so far.
    pub fn reused(&self) -> usize {
        self.reused
    }

    /// Forgets everything when `masks`' views, `model`'s positions or `fill` differ from the
    /// carves kept.
    pub(super) fn carving_from(
        &mut self,
        masks: &ViewMaskSet,
        model: &GaussianModel,
        fill: HullFill,
    ) {
        let mut hasher = DefaultHasher::new();
        for mean in &model.means {
            mean.map(f32::to_bits).hash(&mut hasher);
        }
        let from = CarvedFrom {
            positions: hasher.finish(),
            frames: masks.views.iter().map(|view| view.frame_index).collect(),
            fill,
        };
        if self.carved_from.as_ref() != Some(&from) {
            self.objects = Default::default();
            self.carved_from = Some(from);
        }
    }

    pub(super) fn get(&self, level: Level, object_id: u32) -> Option<&Vec<Vec3>> {
        self.objects[level.index()].get(&object_id)
    }

    pub(super) fn note_reused(&mut self) {
        self.reused += 1;
    }

    pub(super) fn keep(&mut self, level: Level, object_id: u32, points: Vec<Vec3>) {
        self.objects[level.index()].insert(object_id, points);
    }

    /// Forgets the objects whose carve `remaps` change: the merged ids (both sides) and every id
    /// with a pixel next to (8-neighbourhood) a pixel of an id merged away. `masks` are the
    /// masks before the remaps.
    pub fn forget_remapped(&mut self, masks: &ViewMaskSet, remaps: &[IdRemap; 3]) {
        for level in Level::ALL {
            let remap = &remaps[level.index()];
            if remap.is_empty() {
                continue;
            }
            let mut changed: BTreeSet<u32> = remap.keys().chain(remap.values()).copied().collect();
            for view in &masks.views {
                let (width, height) = (view.width as usize, view.height as usize);
                let ids = view.ids(level);
                let merged_away = id_runs(ids).filter(|(id, _)| remap.contains_key(id));
                for pixel in merged_away.flat_map(|(_, pixels)| pixels) {
                    let (x, y) = (pixel % width, pixel / width);
                    for ny in y.saturating_sub(1)..(y + 2).min(height) {
                        for nx in x.saturating_sub(1)..(x + 2).min(width) {
                            changed.insert(ids[ny * width + nx]);
                        }
                    }
                }
            }
            self.objects[level.index()].retain(|id, _| !changed.contains(id));
        }
    }
}
