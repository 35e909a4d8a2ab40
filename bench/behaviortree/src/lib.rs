//! The bench workload ([`workload`]) with [`behaviortree`], a Rust behavior tree library modelled
//! on BehaviorTree.CPP, written as a BehaviorTree.CPP user would: custom nodes registered with the
//! factory, the tree built from a BTCPP v4 XML definition, ticked with `tick_while_running`.
//!
//! The tree ([`PLAN_XML`]) is a `Sequence` of three legs; each leg is a `ReactiveSequence` of the
//! sensor condition `PathClear` and the action `Advance` (BehaviorTree.CPP's tutorial 4 pattern,
//! which `behaviortree` reproduces in its `t04_reactive_sequence` example: a condition re-checked
//! on every tick of the asynchronous action after it). A reactive sequence per action, not one
//! around the whole plan: when an action succeeds, a `Sequence` starts the next one in the same
//! tick, so a single outer `ReactiveSequence` would sample the sensor 28 times for 30 action
//! steps. With one per leg, every action step comes right after exactly one sample.
//!
//! One action step:
//! 1. `PathClear` takes a sample ([`workload::Sonar::sample`]) and returns `Success` if
//!    [`workload::path_clear`] holds on it, else `Failure` (the `ReactiveSequence` then halts the
//!    action and the plan fails);
//! 2. `Advance` reads its progress counter from its `progress` port and writes the incremented
//!    value back. The port is remapped in the XML to a blackboard entry (`{leg1}` …), so the
//!    port is the entry: reading it is a blackboard read, setting it a blackboard write (this is
//!    BehaviorTree.CPP's `getInput`/`setOutput`). It returns `Running` until the counter reaches
//!    [`workload::STEPS_PER_ACTION`], then `Success`.
#![deny(missing_docs)]

#[path = "../../src/workload.rs"]
pub mod workload;

use core::sync::atomic::{AtomicU32, Ordering};

use behaviortree::prelude::*;

/// The plan in BehaviorTree.CPP v4 XML.
pub const PLAN_XML: &str = r#"
<root BTCPP_format="4" main_tree_to_execute="Plan">
    <BehaviorTree ID="Plan">
        <Sequence>
            <ReactiveSequence>
                <PathClear/>
                <Advance progress="{leg1}"/>
            </ReactiveSequence>
            <ReactiveSequence>
                <PathClear/>
                <Advance progress="{leg2}"/>
            </ReactiveSequence>
            <ReactiveSequence>
                <PathClear/>
                <Advance progress="{leg3}"/>
            </ReactiveSequence>
        </Sequence>
    </BehaviorTree>
</root>
"#;

/// The blackboard entries holding the actions' progress, as remapped in [`PLAN_XML`].
pub const PROGRESS_KEYS: [&str; workload::ACTIONS as usize] = ["leg1", "leg2", "leg3"];

/// The plan's range sensor: a [`workload::Sonar`], optionally with one reading replaced by an
/// obstacle (for tests: the plan must then fail).
#[derive(Debug, Default, Clone)]
pub struct Sensor {
    sonar: workload::Sonar,
    samples: u32,
    blocked_at: Option<u32>,
}

impl Sensor {
    /// The workload's sensor: every reading clears the path.
    pub const fn new() -> Self {
        Self {
            sonar: workload::Sonar::new(),
            samples: 0,
            blocked_at: None,
        }
    }

    /// A sensor whose `n`th reading (from 1) sees an obstacle within the threshold.
    pub const fn blocked_at(n: u32) -> Self {
        Self {
            sonar: workload::Sonar::new(),
            samples: 0,
            blocked_at: Some(n),
        }
    }

    /// One reading, mm.
    pub fn sample(&mut self) -> i32 {
        let mm = self.sonar.sample();
        self.samples += 1;
        if self.blocked_at == Some(self.samples) {
            workload::THRESHOLD_MM - 100
        } else {
            mm
        }
    }

    /// Readings taken so far.
    pub const fn samples(&self) -> u32 {
        self.samples
    }
}

/// The sensor, shared by the tree's three `PathClear` nodes and the caller.
pub type SharedSensor = Arc<Mutex<Sensor>>;

/// Condition `PathClear`: samples the sensor; `Success` if the path is clear.
#[derive(Condition)]
#[behavior(no_register)]
struct PathClear {
    #[behavior(parameter)]
    sensor: SharedSensor,
}

#[async_trait::async_trait]
impl Behavior for PathClear {
    async fn tick(
        &mut self,
        _behavior: &mut BehaviorData,
        _children: &mut BehaviorTreeElementList,
        _runtime: &SharedRuntime,
    ) -> BehaviorResult {
        let mm = self.sensor.lock().sample();
        if workload::path_clear(mm) {
            Ok(BehaviorState::Success)
        } else {
            Ok(BehaviorState::Failure)
        }
    }
}

/// Action `Advance`: one step per tick, its progress kept in the blackboard through its
/// in/out port `progress`.
#[derive(Action)]
#[behavior(no_register)]
struct Advance {
    #[behavior(portlist)]
    portlist: PortArray<1>,
    /// Action steps run by all `Advance` nodes (the result of [`run_plan`]).
    #[behavior(parameter)]
    steps: Arc<AtomicU32>,
}

impl Advance {
    port_array_init! {1,
        create_inoutbound_entry!("progress", u32, 0)
    }
}

#[async_trait::async_trait]
impl Behavior for Advance {
    async fn tick(
        &mut self,
        _behavior: &mut BehaviorData,
        _children: &mut BehaviorTreeElementList,
        _runtime: &SharedRuntime,
    ) -> BehaviorResult {
        let progress = self.portlist.get::<u32>("progress")? + 1;
        self.portlist.set("progress", progress)?;
        self.steps.fetch_add(1, Ordering::Relaxed);
        if progress < workload::STEPS_PER_ACTION {
            Ok(BehaviorState::Running)
        } else {
            Ok(BehaviorState::Success)
        }
    }
}

/// A built tree with handles on its sensor and step counter, to run the plan repeatedly.
pub struct Prepared {
    tree: BehaviorTree,
    sensor: SharedSensor,
    steps: Arc<AtomicU32>,
}

impl Prepared {
    /// The tree.
    pub fn tree(&self) -> &BehaviorTree {
        &self.tree
    }

    /// The sensor.
    pub fn sensor(&self) -> &SharedSensor {
        &self.sensor
    }

    /// Action steps run since the tree was built or last reset.
    pub fn steps(&self) -> u32 {
        self.steps.load(Ordering::Relaxed)
    }

    /// Back to the state of a freshly built tree: halts the tree (`BehaviorTree::reset`), sets
    /// the progress entries of the blackboard to 0, restarts the sensor and the step count.
    pub fn reset(&mut self) {
        self.tree.reset().expect("reset the tree");
        let blackboard = self.tree.blackboard_mut();
        for key in PROGRESS_KEYS {
            blackboard.set(key, 0_u32).expect("reset progress");
        }
        let mut sensor = self.sensor.lock();
        *sensor = Sensor {
            sonar: workload::Sonar::new(),
            samples: 0,
            blocked_at: sensor.blocked_at,
        };
        self.steps.store(0, Ordering::Relaxed);
    }

    /// Ticks the tree until it is no longer running; returns its final state and the action
    /// steps it ran.
    pub fn run(&mut self) -> (BehaviorState, u32) {
        let state =
            embassy_futures::block_on(self.tree.tick_while_running()).expect("tick the tree");
        (state, self.steps())
    }
}

/// Builds the tree with the given sensor: a factory, the two custom nodes registered, the tree
/// created from [`PLAN_XML`].
pub fn prepare_with(sensor: Sensor) -> Prepared {
    let sensor: SharedSensor = Arc::new(Mutex::new(sensor));
    let steps = Arc::new(AtomicU32::new(0));
    let mut factory = BehaviorTreeFactory::new().expect("create the factory");
    PathClear::register_with(&mut factory, "PathClear", sensor.clone())
        .expect("register PathClear");
    Advance::register_with(&mut factory, "Advance", steps.clone()).expect("register Advance");
    let tree = factory.create_from_text(PLAN_XML).expect("create the tree");
    Prepared {
        tree,
        sensor,
        steps,
    }
}

/// Builds the tree with the workload's sensor.
pub fn prepare() -> Prepared {
    prepare_with(Sensor::new())
}

/// Runs an already built tree once more (after [`Prepared::reset`]); returns the action steps
/// it ran.
pub fn run_prepared(p: &mut Prepared) -> u32 {
    p.reset();
    p.run().1
}

/// Builds the tree and runs the plan once; returns the action steps it ran.
pub fn run_plan() -> u32 {
    prepare().run().1
}
