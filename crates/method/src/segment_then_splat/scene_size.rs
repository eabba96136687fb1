//! Defaults that depend on the scene (docs/method.md stage 3). The released code trains small
//! scenes (a few dozen views, e.g. 3D-OVS) for 20k steps with one object per level per step and
//! large ones (LERF-style captures of hundreds of frames) for 40k with three, the middle and large
//! levels joining after 5k and 10k steps in both. Those counts are not kept: on a sparse capture
//! (the figurine, 20 training views) held-out quality peaks within a few thousand steps and then
//! falls, and every further step is the user's wait. Here a job's steps follow its training
//! views ([`scene_sized_steps`]: about [`EPOCHS`] passes over them, within a floor and a
//! ceiling), its Gaussians a budget from its pixels (`segsplat_engine::train::budget`), and the
//! levels join at the released code's shares of its length (or its steps, in a run at least as
//! long). A job takes these for every field its config leaves out.

use serde::{Deserialize, Serialize};

use segsplat_engine::deform::DeformationConfig;
use segsplat_engine::train::{ObjectLossConfig, TrainConfig};

/// Scenes with fewer training views than this are "small".
pub const SMALL_SCENE_MAX_VIEWS: usize = 100;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SceneSize {
    Small,
    Large,
}

impl SceneSize {
    pub fn of(training_views: usize) -> Self {
        if training_views < SMALL_SCENE_MAX_VIEWS {
            SceneSize::Small
        } else {
            SceneSize::Large
        }
    }

    /// The released code's steps for a scene of this size (the levels' shares of the job
    /// come from it).
    pub fn released_steps(self) -> u32 {
        match self {
            SceneSize::Small => 20_000,
            SceneSize::Large => 40_000,
        }
    }

    pub fn objects_per_level(self) -> u32 {
        match self {
            SceneSize::Small => 1,
            SceneSize::Large => 3,
        }
    }
}

/// Steps after which the middle level joins, and then the large one (released: 5k and 10k).
const MIDDLE_FROM_STEP: f32 = 5_000.0;
const LARGE_FROM_STEP: f32 = 10_000.0;

/// Passes over the training views a job makes by default. 3DGS's 30k steps are 100-150 passes
/// over a Mip-NeRF 360 capture of 200-300 views; the released 20k steps on the figurine's 20
/// views are 1000, and its held-out PSNR fell from 19.0 dB after 2k steps to 17.3 after 20k.
pub const EPOCHS: u32 = 100;
/// Fewest default steps: the schedule's stages (densification from step 500 of 30k scaled, one
/// SH band every thousandth step of 30k scaled, the level shares) need a few thousand steps
/// to be apart, and a sparse capture's held-out quality peaks later than 100 passes. The
/// figurine's 20 views at 256 px, two seeds in one hour (docs/benchmarks.md, "The job's
/// floor"): 2000 steps 19.66 / 19.04 dB, 3000 steps 20.84 / 20.78, 4000 steps 20.27 / 19.59.
pub const MIN_SCENE_SIZED_STEPS: u32 = 3_000;
/// Most default steps: the 3DGS recipe's.
pub const MAX_SCENE_SIZED_STEPS: u32 = 30_000;

/// The default steps of a job on `training_views` views.
pub fn scene_sized_steps(training_views: usize) -> u32 {
    let passes = (training_views as u64).saturating_mul(EPOCHS as u64);
    passes.clamp(MIN_SCENE_SIZED_STEPS as u64, MAX_SCENE_SIZED_STEPS as u64) as u32
}

/// Which fields of a job's config were left out, and so come from the scene's size.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SceneSizedFields {
    pub steps: bool,
    pub objects_per_level: bool,
    /// `object_loss.middle_from` and `large_from`: the released 5k and 10k steps, or the
    /// released shares of a shorter run (see [`SceneSizedFields::apply`]).
    pub level_schedule: bool,
    /// `object_loss.fade_from_step`: the scene-sized steps, so only a job longer than the scene
    /// needs fades its object loss (`null` keeps the full weight to the end).
    pub object_loss_fade: bool,
    /// `schedule_steps`: the scene-sized steps when the job asks for more, so its schedule is
    /// the scene's and its extra steps polish (`TrainConfig::schedule_steps`).
    pub schedule_steps: bool,
    /// `deformation`: the deformation field (docs/method.md "Dynamic scenes") for scenes whose
    /// frames carry times, none for static ones.
    pub deformation: bool,
    /// `background`: for scenes of RGBA images (Blender, D-NeRF), the colour they are composited
    /// on (white), so transparent pixels are not learnt as a haze of that colour.
    pub background: bool,
}

impl SceneSizedFields {
    /// Reads which fields the submitted JSON config leaves out.
    pub fn left_out_of(submitted: &serde_json::Value) -> Self {
        let absent = |pointer: &str| submitted.pointer(pointer).is_none();
        Self {
            steps: absent("/steps"),
            objects_per_level: absent("/object_loss/objects_per_level"),
            level_schedule: absent("/object_loss/middle_from") && absent("/object_loss/large_from"),
            object_loss_fade: absent("/object_loss/fade_from_step"),
            schedule_steps: absent("/schedule_steps"),
            deformation: absent("/deformation"),
            background: absent("/background"),
        }
    }

    /// Uses the colour transparent images were composited on (`Some` for scenes with RGBA
    /// images: Blender / D-NeRF) when the config left `background` out.
    pub fn apply_background(self, composited_on: Option<[f32; 3]>, config: &mut TrainConfig) {
        if let (true, Some(background)) = (self.background, composited_on) {
            config.background = background;
        }
    }

    /// Turns the deformation field on for a dynamic scene when the config left it out. Its
    /// shape, when left out, is the adapter's: the trainer resolves it
    /// (`DeformationConfig::field_for`).
    pub fn apply_deformation(self, dynamic: bool, config: &mut TrainConfig) {
        if self.deformation && dynamic && config.deformation.is_none() {
            config.deformation = Some(DeformationConfig::default());
        }
    }

    /// Fills the scene-sized fields of `config` for a scene of `training_views` views.
    ///
    /// A job that asks for more steps than the scene needs lays its schedule out over the
    /// scene's steps and polishes after them (`schedule_steps`), and its object loss fades from
    /// there (`fade_from_step`): stretched over five times the steps, the recipe's schedule
    /// overfit the figurine's 20 views (docs/segment_then_splat.md, "Longer than the scene
    /// needs").
    ///
    /// Each level joins at the released code's step (5k, 10k) or at the released code's share
    /// of the object loss's run (a quarter and a half of a small scene's 20k), whichever comes
    /// first, so every level trains in every run; that run is the laid-out steps. A run as long
    /// as the released one or longer keeps the released steps; a shorter one joins at the
    /// shares. The released steps alone left a 4000-step job without its middle and large
    /// levels: on the figurine it held out 18.58 dB, against 20.65 and 20.87 (two seeds) with
    /// the shares (docs/segment_then_splat.md).
    pub fn apply(self, training_views: usize, config: &mut TrainConfig) {
        let size = SceneSize::of(training_views);
        let scene_steps = scene_sized_steps(training_views);
        if self.steps {
            config.steps = scene_steps;
        }
        if self.schedule_steps && config.steps > scene_steps {
            config.schedule_steps = Some(scene_steps);
        }
        let steps = config.steps.max(1);
        let laid_out = config.laid_out_steps();
        // The earlier of the released step and its share of the laid-out run, as a share of
        // the whole job.
        let longer_run = laid_out.max(size.released_steps()) as f32;
        let joins_at = |released_step: f32| {
            (released_step * laid_out as f32 / longer_run / steps as f32).min(1.0)
        };
        let object_loss = config
            .object_loss
            .get_or_insert_with(ObjectLossConfig::default);
        if self.objects_per_level {
            object_loss.objects_per_level = size.objects_per_level();
        }
        if self.level_schedule {
            object_loss.middle_from = joins_at(MIDDLE_FROM_STEP);
            object_loss.large_from = joins_at(LARGE_FROM_STEP);
        }
        if self.object_loss_fade {
            object_loss.fade_from_step = Some(scene_steps);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn left_out_fields_follow_the_scene_size_and_given_ones_stay() {
        let submitted = serde_json::json!({"object_loss": {"objects_per_level": 2}});
        let sized = SceneSizedFields::left_out_of(&submitted);
        assert_eq!(
            sized,
            SceneSizedFields {
                steps: true,
                objects_per_level: false,
                level_schedule: true,
                object_loss_fade: true,
                schedule_steps: true,
                deformation: true,
                background: true,
            }
        );
        let mut config = TrainConfig {
            object_loss: Some(ObjectLossConfig {
                objects_per_level: 2,
                ..ObjectLossConfig::default()
            }),
            ..TrainConfig::default()
        };
        sized.apply(20, &mut config);
        let object_loss = config.object_loss.unwrap();
        assert_eq!(config.steps, 3_000);
        assert_eq!(object_loss.objects_per_level, 2);
        // The released shares of a small scene's 20k steps: middle after a quarter, large after
        // half.
        assert!((object_loss.middle_from - 0.25).abs() < 1e-6);
        assert!((object_loss.large_from - 0.5).abs() < 1e-6);

        let mut large = TrainConfig::default();
        SceneSizedFields::left_out_of(&serde_json::json!({})).apply(180, &mut large);
        let object_loss = large.object_loss.unwrap();
        assert_eq!((large.steps, object_loss.objects_per_level), (18_000, 3));
        assert!((object_loss.middle_from - 0.125).abs() < 1e-6);

        let mut given = TrainConfig::default();
        SceneSizedFields::default().apply(20, &mut given);
        assert_eq!(given.steps, TrainConfig::default().steps);

        // Given steps longer than the scene needs lay the schedule out over the scene's steps,
        // and the levels join at their shares of those (steps 750 and 1500 of 3000)...
        let given = |submitted: serde_json::Value| {
            let mut explicit: TrainConfig =
                serde_json::from_value(submitted.clone()).expect("a train config");
            SceneSizedFields::left_out_of(&submitted).apply(20, &mut explicit);
            let object_loss = explicit.object_loss.expect("the object loss");
            let steps = explicit.steps as f32;
            (
                explicit.schedule_steps,
                (object_loss.middle_from * steps).round() as u32,
                (object_loss.large_from * steps).round() as u32,
            )
        };
        for steps in [4_000, 15_000, 40_000] {
            let laid_out = given(serde_json::json!({ "steps": steps }));
            assert_eq!(laid_out, (Some(3_000), 750, 1_500), "{steps} steps");
        }
        // ...and the scene's own steps (or fewer) need no separate schedule.
        assert_eq!(given(serde_json::json!({})), (None, 750, 1_500));
        assert_eq!(
            given(serde_json::json!({"steps": 2_000})),
            (None, 500, 1_000)
        );
        // A schedule over all the given steps (`null`): a run as long as the released one or
        // longer keeps the released steps (5k and 10k), a shorter one joins at the released
        // shares, so every level trains, and between the two whichever comes first: 30k
        // steps join at 5k and 10k (not 7.5k, 15k).
        let stretched =
            |steps: u32| given(serde_json::json!({"steps": steps, "schedule_steps": null}));
        assert_eq!(stretched(40_000), (None, 5_000, 10_000));
        assert_eq!(stretched(30_000), (None, 5_000, 10_000));
        assert_eq!(stretched(4_000), (None, 1_000, 2_000));
        // A given schedule is kept, and the levels follow it.
        assert_eq!(
            given(serde_json::json!({"steps": 9_000, "schedule_steps": 6_000})),
            (Some(6_000), 1_500, 3_000)
        );
    }

    #[test]
    fn the_object_loss_fades_after_the_scene_sized_steps_unless_given() {
        let fade_of = |submitted: serde_json::Value| {
            let mut config: TrainConfig =
                serde_json::from_value(submitted.clone()).expect("a train config");
            SceneSizedFields::left_out_of(&submitted).apply(20, &mut config);
            config
                .object_loss
                .and_then(|object_loss| object_loss.fade_from_step)
        };
        // Left out: the scene-sized 3000 steps, whatever the job's own steps.
        assert_eq!(fade_of(serde_json::json!({})), Some(3_000));
        assert_eq!(fade_of(serde_json::json!({"steps": 15_000})), Some(3_000));
        // Given, or `null` (the full weight to the end): kept.
        let given = serde_json::json!({"object_loss": {"fade_from_step": 500}});
        assert_eq!(fade_of(given), Some(500));
        let never = serde_json::json!({"object_loss": {"fade_from_step": null}});
        assert_eq!(fade_of(never), None);
    }

    #[test]
    fn scene_sized_steps_are_passes_over_the_views_within_bounds() {
        assert_eq!(scene_sized_steps(3), MIN_SCENE_SIZED_STEPS);
        assert_eq!(scene_sized_steps(20), 3_000);
        assert_eq!(scene_sized_steps(30), 3_000);
        assert_eq!(scene_sized_steps(31), 3_100);
        assert_eq!(scene_sized_steps(100), 10_000);
        assert_eq!(scene_sized_steps(1_000), MAX_SCENE_SIZED_STEPS);
    }

    #[test]
    fn deformation_follows_the_scene_unless_given() {
        let left_out = SceneSizedFields::left_out_of(&serde_json::json!({}));
        let mut dynamic = TrainConfig::default();
        left_out.apply_deformation(true, &mut dynamic);
        assert_eq!(dynamic.deformation, Some(DeformationConfig::default()));
        let mut static_scene = TrainConfig::default();
        left_out.apply_deformation(false, &mut static_scene);
        assert_eq!(static_scene.deformation, None);
        // An explicit `"deformation": null` keeps a dynamic scene static.
        let given = SceneSizedFields::left_out_of(&serde_json::json!({"deformation": null}));
        let mut forced_static = TrainConfig::default();
        given.apply_deformation(true, &mut forced_static);
        assert_eq!(forced_static.deformation, None);
    }
}
