//! [`PairSource`]s for the evaluation loop: a dataset split ([`DatasetSource`]) and pairs simulated on the fly
//! ([`SimSource`], the test bed for the pipeline before a dataset exists).

use super::evaluate::{EvalError, EvalPair, PairSource};
use crate::dataset::{Dataset, SplitName};
use crate::objects::ObjectSet;
use crate::pose::camera_path::CameraPath;
use crate::pose::SensorContext;
use crate::sensor::{Scene, Se2};
use crate::sim::{PreparedObject, SimConfig, Simulator};

/// The pairs of one dataset split (optionally `limit` pairs after skipping the first `skip`).
pub struct DatasetSource<'a> {
    dataset: &'a Dataset,
    split: SplitName,
    /// Index in the split of this source's pair 0.
    skip: usize,
    len: usize,
    ctx: SensorContext,
    t_sensor_camera: glam::DAffine3,
}

impl<'a> DatasetSource<'a> {
    /// Open `split` of `dataset`, at most `limit` pairs.
    pub fn new(
        dataset: &'a Dataset,
        split: SplitName,
        limit: Option<usize>,
    ) -> Result<Self, EvalError> {
        let sim =
            Simulator::new(dataset.sim_config().clone()).map_err(|source| EvalError::Sensor {
                dir: dataset.dir().to_path_buf(),
                source,
            })?;
        let objects = dataset.object_set()?;
        let n = dataset.len(split);
        let mut ctx = SensorContext::of_simulator(&sim, objects);
        ctx.camera_path =
            CameraPath::for_frames(dataset.sim_config(), dataset.manifest().frames_resampled())
                .map_err(|source| EvalError::Sensor {
                    dir: dataset.dir().to_path_buf(),
                    source,
                })?;
        Ok(Self {
            dataset,
            split,
            skip: 0,
            len: limit.map_or(n, |l| l.min(n)),
            ctx,
            t_sensor_camera: sim.t_sensor_camera(),
        })
    }
}

impl DatasetSource<'_> {
    /// Start at pair `skip` of the split (pairs already looked at, e.g. while tuning, stay out of a test figure);
    /// the limit then counts from there.
    pub fn skip(mut self, skip: usize, limit: Option<usize>) -> Self {
        let n = self.dataset.len(self.split).saturating_sub(skip);
        self.skip = skip;
        self.len = limit.map_or(n, |l| l.min(n));
        self
    }
}

impl PairSource for DatasetSource<'_> {
    fn len(&self) -> usize {
        self.len
    }

    fn pair(&self, index: usize) -> Result<EvalPair, EvalError> {
        let index = index + self.skip;
        let p = self.dataset.pair(self.split, index)?;
        if !p.meta.sensor.position.iter().all(|v| v.is_finite()) {
            return Err(EvalError::Source(format!(
                "{}: pair {}/{index} has no sensor pose (imported data without press depth); pose metrics need it",
                self.dataset.dir().display(),
                self.split
            )));
        }
        Ok(EvalPair {
            name: format!("{}/{index}", self.split),
            object: p.meta.object.clone(),
            object_pose: p.meta.object_pose,
            t_world_camera: p.meta.sensor.t_world_sensor() * self.t_sensor_camera,
            target: p.target,
            signature: p.signature,
            imprint: p.imprint,
        })
    }

    fn context(&self) -> &SensorContext {
        &self.ctx
    }
}

/// One simulated contact: object, its pose, and the press depth (sensor above the world origin, yaw 0).
#[derive(Clone, Debug, PartialEq)]
pub struct SimSpec {
    pub object: String,
    pub pose: Se2,
    /// Metres.
    pub press: f64,
    /// Signature noise seed.
    pub seed: u64,
}

/// Pairs simulated on demand from [`SimSpec`]s.
pub struct SimSource {
    sim: Simulator,
    specs: Vec<SimSpec>,
    ctx: SensorContext,
}

impl SimSource {
    pub fn new(
        config: SimConfig,
        objects: ObjectSet,
        specs: Vec<SimSpec>,
    ) -> Result<Self, EvalError> {
        let sim = Simulator::new(config).map_err(|source| EvalError::Sensor {
            dir: "simulated pairs".into(),
            source,
        })?;
        let ctx = SensorContext::of_simulator(&sim, objects);
        Ok(Self { sim, specs, ctx })
    }
}

impl PairSource for SimSource {
    fn len(&self) -> usize {
        self.specs.len()
    }

    fn pair(&self, index: usize) -> Result<EvalPair, EvalError> {
        let spec = self
            .specs
            .get(index)
            .ok_or_else(|| EvalError::Source(format!("no simulated pair {index}")))?;
        let mesh = self.ctx.objects.mesh(&spec.object)?;
        let object = PreparedObject::new(mesh)?;
        let sensor = self.sim.pressing_pose(&object, 0.0, 0.0, 0.0, spec.press);
        let out = self.sim.simulate(
            &object,
            &Scene {
                object: spec.pose,
                sensor,
            },
            spec.seed,
        );
        Ok(EvalPair {
            name: format!("sim/{index}"),
            object: spec.object.clone(),
            object_pose: spec.pose,
            t_world_camera: self.sim.t_world_camera(&sensor),
            target: out.target,
            signature: out.signature,
            imprint: out.imprint,
        })
    }

    fn context(&self) -> &SensorContext {
        &self.ctx
    }
}
