//! The simulated camera: renders each frame from the TRUE chain of the simulated cell (true flange
//! pose, true hand-eye and base-world), so the solver, which sees only the rendered frames and
//! the robot's noisy reported poses, has something real to recover. Each frame's `captured_at`
//! is its exposure start: the moment whose flange pose it shows (a frame exposed while the arm
//! still rings down shows the arm off its resting pose).

use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::Instant;

use rand::rngs::StdRng;
use rand::SeedableRng;

use handeye_core::geometry::Pose;
use handeye_core::setup::CellTransforms;
use handeye_vision::Target;

use super::render::{render_with_rays, PixelRays, RenderOptions};
use super::{Camera, CameraError, Frame};
use handeye_core::camera_model::CameraModel;

/// Where the simulated camera learns the arm's true flange pose `T_base_flange`.
pub type TrueFlangePose = Box<dyn Fn() -> Pose + Send>;

/// A camera that renders the board as the simulated cell truly is.
pub struct SimCamera {
    /// The lens it renders with.
    lens: CameraModel,
    /// The intrinsics it reports (what the cell believes; `lens` unless told otherwise).
    model: CameraModel,
    board: Target,
    truth: CellTransforms,
    true_base_from_flange: TrueFlangePose,
    options: RenderOptions,
    rng: StdRng,
    hidden_grabs: BTreeSet<usize>,
    grabs: usize,
    /// The lens's pixel rays, taken at the first grab and reused by every frame (shared with the
    /// other cameras of the same lens, [`PixelRays::shared`]).
    rays: Option<Arc<PixelRays>>,
}

impl SimCamera {
    /// A simulated camera. `hidden_grabs` lists grab numbers (0-based) in which something blocks
    /// the view of the board (fault injection).
    pub fn new(
        model: CameraModel,
        board: Target,
        truth: CellTransforms,
        true_base_from_flange: TrueFlangePose,
        options: RenderOptions,
        seed: u64,
        hidden_grabs: BTreeSet<usize>,
    ) -> Self {
        SimCamera {
            lens: model,
            model,
            board,
            truth,
            true_base_from_flange,
            options,
            rng: StdRng::seed_from_u64(seed),
            hidden_grabs,
            grabs: 0,
            rays: None,
        }
    }

    /// The same camera reporting `model` as its intrinsics while it renders with its own lens: a
    /// camera whose calibration file is wrong.
    pub fn reporting(mut self, model: CameraModel) -> Self {
        self.model = model;
        self
    }
}

impl Camera for SimCamera {
    fn grab(&mut self, not_before: Instant) -> Result<Frame, CameraError> {
        // A free-running camera's next exposure starts no earlier than asked; the exposure is
        // taken as instantaneous, at the arm's pose at that moment.
        let now = Instant::now();
        if not_before > now {
            std::thread::sleep(not_before - now);
        }
        let exposure_start = Instant::now();
        let grab = self.grabs;
        self.grabs += 1;
        let camera_from_target = if self.hidden_grabs.contains(&grab) {
            // The board is behind the camera: the frame shows only the background.
            Pose::translation(0.0, 0.0, -10.0)
        } else {
            self.truth
                .camera_from_target(&(self.true_base_from_flange)())
        };
        // Under a memory limit the table or the frame may not fit: a camera error that ends the
        // run cleanly with what it recorded, never an abort.
        let rays = match &self.rays {
            Some(rays) => rays,
            None => self.rays.insert(PixelRays::shared(&self.lens)?),
        };
        let image = render_with_rays(
            &self.board,
            &self.lens,
            rays,
            &camera_from_target,
            &self.options,
            &mut self.rng,
        )?;
        // The frame reports when its exposure started (it shows the arm as it stood then),
        // never before `not_before`.
        Ok(Frame {
            image,
            captured_at: exposure_start,
            png: None,
        })
    }

    fn model(&self) -> &CameraModel {
        &self.model
    }
}
