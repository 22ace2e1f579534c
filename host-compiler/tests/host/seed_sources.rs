//! The seed interface (`cover::seeds`, issue 48 item 5) and the report's routes (item 7): every
//! trajectory keeps where it came from, the growth records the routes it searched, and the report of a
//! routed cover draws them and names the route each trajectory came from.

use host_compiler::cover::seeds::{Ask, Origin, Seed, Source};
use host_compiler::report::{render_html, report_data};
use host_compiler::synth::{synthesize, SynthOptions};
use host_compiler::task::Task;

#[test]
fn a_source_reads_as_the_loops_wrote_it_and_a_seed_asks_in_order() {
    let s = |o, opt| Source::new(o, opt).to_string();
    assert_eq!(s(Origin::Generator, false), "generated");
    assert_eq!(s(Origin::Generator, true), "generated (SCP) + §5.3");
    assert_eq!(s(Origin::Route(1), false), "route 2 (SCP)");
    assert_eq!(s(Origin::Route(0), true), "route 1 (SCP) + §5.3");
    assert_eq!(s(Origin::Algorithm4(3), true), "Algorithm 4 from #3 + §5.3");
    assert_eq!(Source::import("a.csv").to_string(), "csv:a.csv");
    assert_eq!(Source::new(Origin::Route(2), true).route(), Some(2));
    assert_eq!(Source::new(Origin::Algorithm4(2), true).route(), None);
    // certificate.json keeps the text.
    let json = serde_json::to_string(&Source::new(Origin::Route(0), true)).unwrap();
    assert_eq!(json, "\"route 1 (SCP) + §5.3\"");
    // Algorithm 4 first (when the seed has a ball), then the generator, then the routes.
    let plain = Seed::at(vec![0.0, 0.0]);
    assert_eq!(plain.asks(), vec![Ask::Generator, Ask::Routes]);
    let grown = Seed {
        x: vec![0.0, 0.0],
        grow: Some((4, vec![0.1, 0.0])),
    };
    assert_eq!(grown.asks(), vec![Ask::Grow, Ask::Generator, Ask::Routes]);
}

/// Two walls between Init and Goal in a bounded box, for a point mass: the plain generator from Init's
/// centre does not get through (`route_search` shows it), a route does.
fn two_walls() -> String {
    r#"
name = "two-walls"
seed = 7
horizon = 30.0
[plant]
time = "continuous"
A = [[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]]
B = [[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]
period = 0.3
[init]
kind = "box"
lo = [0.48, 0.48, 0.0, 0.0]
hi = [0.52, 0.52, 0.0, 0.0]
[goal]
kind = "box"
lo = [3.6, 0.2]
hi = [4.1, 0.7]
coords = ["x1", "x2"]
[input]
kind = "box"
lo = [-1.0, -1.0]
hi = [1.0, 1.0]
[[unsafe]]
kind = "box"
lo = [1.0, 0.0]
hi = [1.2, 3.0]
coords = ["x1", "x2"]
[[unsafe]]
kind = "box"
lo = [2.2, 1.0]
hi = [2.4, 4.0]
coords = ["x1", "x2"]
[[unsafe]]
kind = "polytope"
A = [[1.0, 0.0]]
b = [0.0]
coords = ["x1", "x2"]
[[unsafe]]
kind = "polytope"
A = [[-1.0, 0.0]]
b = [-4.5]
coords = ["x1", "x2"]
[[unsafe]]
kind = "polytope"
A = [[0.0, 1.0]]
b = [0.0]
coords = ["x1", "x2"]
[[unsafe]]
kind = "polytope"
A = [[0.0, -1.0]]
b = [-4.0]
coords = ["x1", "x2"]
[synthesis]
max_trajectories = 3
"#
    .to_string()
}

#[test]
fn the_report_of_a_routed_cover_draws_its_routes_and_names_each_trajectorys_route() {
    let p = host_compiler::spec::parse(&two_walls(), "two-walls.toml").unwrap();
    let task = Task::new(p.clone()).unwrap();
    let s = synthesize(
        &task,
        &SynthOptions {
            verify_interior: 200,
            verify_per_ball: 2,
            progress: false,
            attack: None,
            ..SynthOptions::default()
        },
    )
    .unwrap();
    // The cover records the searches it ran, and its first trajectory came from a route of one.
    assert!(!s.routes.is_empty());
    let k = s.trajectories[0]
        .source
        .route()
        .unwrap_or_else(|| panic!("{}", s.trajectories[0].source));
    let search = s
        .routes
        .iter()
        .find(|r| r.seed == s.trajectories[0].nominal.x[0])
        .expect("the search from the trajectory's seed is recorded");
    assert!(k < search.routes.len() && search.routes.len() >= 2);
    // The report lists the routes in the workspace plane and names trajectory #0's.
    let data = report_data(&p, "two-walls.toml", &s, "controller.img");
    let r = data.trajectories[0].route.expect("trajectory #0's route");
    let route = &data.routes[r];
    assert!(
        route.label.starts_with(&format!("route {}", k + 1)),
        "{}",
        route.label
    );
    assert!(route.trajectories.contains(&0));
    assert!(data.routes.iter().all(|r| r.points.len() >= 2));
    // Algorithm 4's trajectories count for the route of the ball they grew from.
    for t in &data.trajectories {
        if let Some(j) = t.source.strip_prefix("Algorithm 4 from #") {
            let j: usize = j.split(' ').next().unwrap().parse().unwrap();
            assert_eq!(t.route, data.trajectories[j].route);
        }
    }
    let html = render_html(&data);
    assert!(html.contains("id=\"route-table\""));
    // Drawn in the workspace plot, with its name, and listed with its trajectories.
    let workspace =
        &html[html.find("id=\"workspace\"").unwrap()..html.find("id=\"init-plane\"").unwrap()];
    // (plotters writes a text's content on its own line)
    assert!(
        workspace.contains(&format!("\n{}\n</text>", route.label)),
        "the route's name is not drawn"
    );
    let table = &html[html.find("id=\"route-table\"").unwrap()..];
    assert!(table.contains(&format!("{}</td>", route.label)));
}
