//! Classic planning problems, generated: gripper with `n` balls, the blocks world with `n`
//! blocks and a small logistics problem, as psmpa missions (for `psmpa-sim plan` and the tests) and as PDDL (for pyperplan,
//! the independent planner `cargo xtask bench` compares with). Their optimal plan lengths are
//! known in closed form.

use serde_json::json;

/// A grounded STRIPS action.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Action {
    /// Name, as PDDL writes a grounded action: `pick ball1 rooma left`.
    pub name: String,
    /// Precondition.
    pub pre: Vec<String>,
    /// Add list.
    pub add: Vec<String>,
    /// Delete list.
    pub del: Vec<String>,
}

/// A planning problem, grounded, with its PDDL and the length of its optimal plans.
#[derive(Clone, Debug)]
pub struct Problem {
    /// Name: `gripper-6`, `blocks-10-swap`.
    pub name: String,
    /// Every fact.
    pub facts: Vec<String>,
    /// Every action.
    pub actions: Vec<Action>,
    /// Initial state.
    pub init: Vec<String>,
    /// Goal.
    pub goal: Vec<String>,
    /// Length of an optimal plan.
    pub optimal: usize,
    /// PDDL domain.
    pub pddl_domain: &'static str,
    /// PDDL problem.
    pub pddl_problem: String,
}

fn action(name: String, pre: &[&String], add: &[&String], del: &[&String]) -> Action {
    let own = |v: &[&String]| v.iter().map(|s| (*s).clone()).collect();
    Action {
        name,
        pre: own(pre),
        add: own(add),
        del: own(del),
    }
}

impl Problem {
    /// The problem as a psmpa mission (no sensors, no library plans).
    pub fn mission_json(&self) -> String {
        let actions: Vec<_> = self
            .actions
            .iter()
            .map(|a| json!({"name": a.name, "pre": a.pre, "add": a.add, "del": a.del}))
            .collect();
        json!({
            "name": self.name,
            "facts": self.facts,
            "events": ["solve"],
            "sensors": [],
            "actions": actions,
            "plans": [],
            "task": {"event": "solve", "init": self.init, "goal": self.goal},
        })
        .to_string()
    }
}

const GRIPPER_PDDL: &str = "(define (domain gripper-strips)
  (:predicates (room ?r) (ball ?b) (gripper ?g) (at-robby ?r) (at ?b ?r) (free ?g) (carry ?o ?g))
  (:action move :parameters (?from ?to)
    :precondition (and (room ?from) (room ?to) (at-robby ?from))
    :effect (and (at-robby ?to) (not (at-robby ?from))))
  (:action pick :parameters (?obj ?room ?gripper)
    :precondition (and (ball ?obj) (room ?room) (gripper ?gripper) (at ?obj ?room) (at-robby ?room) (free ?gripper))
    :effect (and (carry ?obj ?gripper) (not (at ?obj ?room)) (not (free ?gripper))))
  (:action drop :parameters (?obj ?room ?gripper)
    :precondition (and (ball ?obj) (room ?room) (gripper ?gripper) (carry ?obj ?gripper) (at-robby ?room))
    :effect (and (at ?obj ?room) (free ?gripper) (not (carry ?obj ?gripper)))))
";

/// Gripper: a robot with two hands carries `balls` balls from room a to room b. Optimal:
/// `6 · ⌊n/2⌋ - 1` moves for even `n`, `6 · ⌊n/2⌋ + 3` for odd `n` (a round trip per pair).
pub fn gripper(balls: usize) -> Problem {
    let rooms = ["rooma", "roomb"];
    let hands = ["left", "right"];
    let robby = |r: &str| format!("at-robby {r}");
    let at = |b: usize, r: &str| format!("at ball{b} {r}");
    let free = |g: &str| format!("free {g}");
    let carry = |b: usize, g: &str| format!("carry ball{b} {g}");
    let mut facts: Vec<String> = rooms.iter().map(|r| robby(r)).collect();
    facts.extend(hands.iter().map(|g| free(g)));
    for b in 1..=balls {
        facts.extend(rooms.iter().map(|r| at(b, r)));
        facts.extend(hands.iter().map(|g| carry(b, g)));
    }
    let mut actions = Vec::new();
    for from in rooms {
        for to in rooms {
            if from != to {
                let (f, t) = (robby(from), robby(to));
                actions.push(action(format!("move {from} {to}"), &[&f], &[&t], &[&f]));
            }
        }
    }
    for b in 1..=balls {
        for r in rooms {
            for g in hands {
                let (a, rb, fr, c) = (at(b, r), robby(r), free(g), carry(b, g));
                actions.push(action(
                    format!("pick ball{b} {r} {g}"),
                    &[&a, &rb, &fr],
                    &[&c],
                    &[&a, &fr],
                ));
                actions.push(action(
                    format!("drop ball{b} {r} {g}"),
                    &[&c, &rb],
                    &[&a, &fr],
                    &[&c],
                ));
            }
        }
    }
    let mut init = vec![robby("rooma"), free("left"), free("right")];
    init.extend((1..=balls).map(|b| at(b, "rooma")));
    let goal: Vec<String> = (1..=balls).map(|b| at(b, "roomb")).collect();
    let pairs = balls / 2;
    let optimal = if balls.is_multiple_of(2) {
        (6 * pairs).saturating_sub(1)
    } else {
        6 * pairs + 3
    };
    let objects: Vec<String> = (1..=balls).map(|b| format!("ball{b}")).collect();
    let pddl_problem = format!(
        "(define (problem gripper-{balls}) (:domain gripper-strips)\n  (:objects rooma roomb left right {})\n  (:init (room rooma) (room roomb) (gripper left) (gripper right) (at-robby rooma) (free left) (free right) {})\n  (:goal (and {})))\n",
        objects.join(" "),
        objects
            .iter()
            .map(|b| format!("(ball {b}) (at {b} rooma)"))
            .collect::<Vec<_>>()
            .join(" "),
        objects
            .iter()
            .map(|b| format!("(at {b} roomb)"))
            .collect::<Vec<_>>()
            .join(" "),
    );
    Problem {
        name: format!("gripper-{balls}"),
        facts,
        actions,
        init,
        goal,
        optimal,
        pddl_domain: GRIPPER_PDDL,
        pddl_problem,
    }
}

const BLOCKS_PDDL: &str = "(define (domain blocks)
  (:predicates (on ?x ?y) (ontable ?x) (clear ?x) (handempty) (holding ?x))
  (:action pick-up :parameters (?x)
    :precondition (and (clear ?x) (ontable ?x) (handempty))
    :effect (and (not (ontable ?x)) (not (clear ?x)) (not (handempty)) (holding ?x)))
  (:action put-down :parameters (?x)
    :precondition (holding ?x)
    :effect (and (not (holding ?x)) (clear ?x) (handempty) (ontable ?x)))
  (:action stack :parameters (?x ?y)
    :precondition (and (holding ?x) (clear ?y))
    :effect (and (not (holding ?x)) (not (clear ?y)) (clear ?x) (handempty) (on ?x ?y)))
  (:action unstack :parameters (?x ?y)
    :precondition (and (on ?x ?y) (clear ?x) (handempty))
    :effect (and (holding ?x) (clear ?y) (not (clear ?x)) (not (handempty)) (not (on ?x ?y)))))
";

/// The blocks world with `n` blocks in one tower `b1` (top) on `b2` ... on `bn` (on the
/// table). `reverse`: the goal is the tower upside down (optimal `2n`); else the top two
/// blocks swapped (`b2` on `b1` on `b3`, optimal 8 for `n >= 3`).
pub fn blocks(n: usize, reverse: bool) -> Problem {
    let b = |i: usize| format!("b{i}");
    let on = |x: usize, y: usize| format!("on b{x} b{y}");
    let table = |x: usize| format!("ontable b{x}");
    let clear = |x: usize| format!("clear b{x}");
    let holding = |x: usize| format!("holding b{x}");
    let hand = "handempty".to_owned();
    let mut facts = vec![hand.clone()];
    for x in 1..=n {
        facts.extend([table(x), clear(x), holding(x)]);
        facts.extend((1..=n).filter(|y| *y != x).map(|y| on(x, y)));
    }
    let mut actions = Vec::new();
    for x in 1..=n {
        let (t, c, h) = (table(x), clear(x), holding(x));
        actions.push(action(
            format!("pick-up b{x}"),
            &[&c, &t, &hand],
            &[&h],
            &[&t, &c, &hand],
        ));
        actions.push(action(
            format!("put-down b{x}"),
            &[&h],
            &[&t, &c, &hand],
            &[&h],
        ));
        for y in (1..=n).filter(|y| *y != x) {
            let (o, cy) = (on(x, y), clear(y));
            actions.push(action(
                format!("stack b{x} b{y}"),
                &[&h, &cy],
                &[&o, &c, &hand],
                &[&h, &cy],
            ));
            actions.push(action(
                format!("unstack b{x} b{y}"),
                &[&o, &c, &hand],
                &[&h, &cy],
                &[&o, &c, &hand],
            ));
        }
    }
    let mut init = vec![hand.clone(), clear(1), table(n)];
    init.extend((1..n).map(|x| on(x, x + 1)));
    let (goal, optimal, what) = if reverse {
        let mut goal = vec![table(1)];
        goal.extend((2..=n).map(|x| on(x, x - 1)));
        (goal, 2 * n, "reverse")
    } else {
        let mut goal = vec![on(2, 1), on(1, 3)];
        goal.extend((3..n).map(|x| on(x, x + 1)));
        (goal, 8, "swap")
    };
    let pddl = |facts: &[String]| {
        facts
            .iter()
            .map(|f| format!("({f})"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let objects: Vec<String> = (1..=n).map(b).collect();
    let pddl_problem = format!(
        "(define (problem blocks-{n}-{what}) (:domain blocks)\n  (:objects {})\n  (:init {})\n  (:goal (and {})))\n",
        objects.join(" "),
        pddl(&init),
        pddl(&goal)
    );
    Problem {
        name: format!("blocks-{n}-{what}"),
        facts,
        actions,
        init,
        goal,
        optimal,
        pddl_domain: BLOCKS_PDDL,
        pddl_problem,
    }
}

const LOGISTICS_PDDL: &str = "(define (domain logistics)
  (:predicates (package ?p) (truck ?t) (airplane ?a) (airport ?l) (location ?l) (in-city ?l ?c)
    (at ?o ?l) (in ?p ?v))
  (:action load-truck :parameters (?p ?t ?l)
    :precondition (and (package ?p) (truck ?t) (location ?l) (at ?t ?l) (at ?p ?l))
    :effect (and (not (at ?p ?l)) (in ?p ?t)))
  (:action unload-truck :parameters (?p ?t ?l)
    :precondition (and (package ?p) (truck ?t) (location ?l) (at ?t ?l) (in ?p ?t))
    :effect (and (not (in ?p ?t)) (at ?p ?l)))
  (:action drive-truck :parameters (?t ?from ?to ?c)
    :precondition (and (truck ?t) (location ?from) (location ?to) (at ?t ?from) (in-city ?from ?c) (in-city ?to ?c))
    :effect (and (not (at ?t ?from)) (at ?t ?to)))
  (:action load-airplane :parameters (?p ?a ?l)
    :precondition (and (package ?p) (airplane ?a) (airport ?l) (at ?p ?l) (at ?a ?l))
    :effect (and (not (at ?p ?l)) (in ?p ?a)))
  (:action unload-airplane :parameters (?p ?a ?l)
    :precondition (and (package ?p) (airplane ?a) (airport ?l) (in ?p ?a) (at ?a ?l))
    :effect (and (not (in ?p ?a)) (at ?p ?l)))
  (:action fly-airplane :parameters (?a ?from ?to)
    :precondition (and (airplane ?a) (airport ?from) (airport ?to) (at ?a ?from))
    :effect (and (not (at ?a ?from)) (at ?a ?to))))
";

/// Logistics' `load-KIND` and `unload-KIND` of package `p` into and out of `vehicle` at
/// `place`.
fn carry(actions: &mut Vec<Action>, kind: &str, p: &str, vehicle: &str, place: &str) {
    let (here, parcel, inside) = (
        format!("at {vehicle} {place}"),
        format!("at {p} {place}"),
        format!("in {p} {vehicle}"),
    );
    actions.push(action(
        format!("load-{kind} {p} {vehicle} {place}"),
        &[&here, &parcel],
        &[&inside],
        &[&parcel],
    ));
    actions.push(action(
        format!("unload-{kind} {p} {vehicle} {place}"),
        &[&here, &inside],
        &[&parcel],
        &[&inside],
    ));
}

/// A small logistics problem: two cities, each with an airport and a post office and a truck
/// at the airport, one airplane at the first city's airport, and `packages` packages to carry
/// from the first city's post office to the second's. Optimal: `4 + 6 · packages` (the first
/// truck fetches them, the plane flies once, the second truck delivers).
pub fn logistics(packages: usize) -> Problem {
    let cities = ["c1", "c2"];
    let places = ["c1-airport", "c1-office", "c2-airport", "c2-office"];
    let city = |l: &str| if l.starts_with("c1") { "c1" } else { "c2" };
    let trucks = ["t1", "t2"];
    let truck_city = |t: &str| if t == "t1" { "c1" } else { "c2" };
    let at = |o: &str, l: &str| format!("at {o} {l}");
    let inside = |p: &str, v: &str| format!("in {p} {v}");
    let ps: Vec<String> = (1..=packages).map(|i| format!("p{i}")).collect();
    let mut facts = Vec::new();
    for l in places {
        for t in trucks.iter().filter(|t| truck_city(t) == city(l)) {
            facts.push(at(t, l));
        }
        if l.ends_with("airport") {
            facts.push(at("plane", l));
        }
        facts.extend(ps.iter().map(|p| at(p, l)));
    }
    for p in &ps {
        facts.extend(trucks.iter().map(|t| inside(p, t)));
        facts.push(inside(p, "plane"));
    }
    let mut actions = Vec::new();
    for t in trucks {
        let here = places.iter().filter(|l| city(l) == truck_city(t));
        for from in here.clone() {
            for to in here.clone().filter(|to| *to != from) {
                let (f, g) = (at(t, from), at(t, to));
                actions.push(action(
                    format!("drive-truck {t} {from} {to} {}", city(from)),
                    &[&f],
                    &[&g],
                    &[&f],
                ));
            }
            for p in &ps {
                carry(&mut actions, "truck", p, t, from);
            }
        }
    }
    let airports = ["c1-airport", "c2-airport"];
    for from in airports {
        for to in airports.iter().filter(|to| **to != from) {
            let (f, g) = (at("plane", from), at("plane", to));
            actions.push(action(
                format!("fly-airplane plane {from} {to}"),
                &[&f],
                &[&g],
                &[&f],
            ));
        }
        for p in &ps {
            carry(&mut actions, "airplane", p, "plane", from);
        }
    }
    let mut init = vec![
        at("t1", "c1-airport"),
        at("t2", "c2-airport"),
        at("plane", "c1-airport"),
    ];
    init.extend(ps.iter().map(|p| at(p, "c1-office")));
    let goal: Vec<String> = ps.iter().map(|p| at(p, "c2-office")).collect();
    let pddl = |facts: &[String]| {
        facts
            .iter()
            .map(|f| format!("({f})"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let statics = format!(
        "(truck t1) (truck t2) (airplane plane) (airport c1-airport) (airport c2-airport) {} {}",
        places
            .iter()
            .map(|l| format!("(location {l}) (in-city {l} {})", city(l)))
            .collect::<Vec<_>>()
            .join(" "),
        ps.iter()
            .map(|p| format!("(package {p})"))
            .collect::<Vec<_>>()
            .join(" "),
    );
    let pddl_problem = format!(
        "(define (problem logistics-{packages}) (:domain logistics)\n  (:objects t1 t2 plane {} {} {})\n  (:init {statics} {})\n  (:goal (and {})))\n",
        cities.join(" "),
        places.join(" "),
        ps.join(" "),
        pddl(&init),
        pddl(&goal)
    );
    Problem {
        name: format!("logistics-{packages}"),
        facts,
        actions,
        init,
        goal,
        optimal: 4 + 6 * packages,
        pddl_domain: LOGISTICS_PDDL,
        pddl_problem,
    }
}

/// The problems `cargo xtask bench` and the tests plan on.
pub fn suite() -> Vec<Problem> {
    vec![
        gripper(4),
        gripper(6),
        gripper(8),
        blocks(4, true),
        blocks(6, true),
        blocks(10, false),
        blocks(12, false),
        logistics(2),
        logistics(3),
    ]
}
