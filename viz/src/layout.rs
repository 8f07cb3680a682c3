//! A small Rerun blueprint builder: containers, views, and view *properties* (plot legend,
//! axis ranges, 3D eye, visible time ranges). The SDK's Rust blueprint API has containers and
//! views but cannot set view properties yet, and a first screen with 40 legend entries over
//! the plots or a camera looking at the volume from below is not useful; so the blueprint is
//! written here from the same archetypes the SDKs use (`view/<id>/<Property>` entities in a
//! blueprint store), and sent with [`RecordingStream::send_blueprint`].

use crate::rerun::blueprint::components::{
    AutoLayout, AutoViews, ColumnShare, ContainerKind, GridColumns, IncludedContent, PanelState, PlayState,
    QueryExpression, RootContainer, RowShare, TimelineName, ViewClass,
};
use crate::rerun::external::re_log_types::{BlueprintActivationCommand, LogMsg};
use crate::rerun::external::re_sdk_types::blueprint::archetypes as bp;
use crate::rerun::external::re_sdk_types::components::{Name, Visible};
use crate::rerun::{AsComponents, RecordingStream, RecordingStreamResult, SerializedComponentBatch};

/// A container or a view.
pub enum Node {
    Container(Container),
    View(View),
}

/// Horizontal, vertical, grid or tab container.
pub struct Container {
    id: [u8; 16],
    kind: ContainerKind,
    name: Option<String>,
    children: Vec<Node>,
    shares: Option<Vec<f32>>,
    grid_columns: Option<u32>,
}

/// One view: its class, title, entity query and properties.
pub struct View {
    id: [u8; 16],
    class: &'static str,
    name: String,
    contents: Vec<String>,
    properties: Vec<(&'static str, Vec<SerializedComponentBatch>)>,
}

fn new_id() -> [u8; 16] {
    let mut b: [u8; 16] = rand::random();
    b[6] = (b[6] & 0x0f) | 0x40; // version 4
    b[8] = (b[8] & 0x3f) | 0x80; // RFC 4122 variant
    b
}

fn uuid_string(b: &[u8; 16]) -> String {
    let h: String = b.iter().map(|x| format!("{x:02x}")).collect();
    format!("{}-{}-{}-{}-{}", &h[0..8], &h[8..12], &h[12..16], &h[16..20], &h[20..32])
}

impl Container {
    fn new(kind: ContainerKind, children: impl IntoIterator<Item = Node>) -> Container {
        Container {
            id: new_id(),
            kind,
            name: None,
            children: children.into_iter().collect(),
            shares: None,
            grid_columns: None,
        }
    }
    pub fn horizontal(children: impl IntoIterator<Item = Node>) -> Container {
        Container::new(ContainerKind::Horizontal, children)
    }
    pub fn vertical(children: impl IntoIterator<Item = Node>) -> Container {
        Container::new(ContainerKind::Vertical, children)
    }
    pub fn grid(columns: u32, children: impl IntoIterator<Item = Node>) -> Container {
        Container { grid_columns: Some(columns), ..Container::new(ContainerKind::Grid, children) }
    }
    pub fn tabs(children: impl IntoIterator<Item = Node>) -> Container {
        Container::new(ContainerKind::Tabs, children)
    }
    pub fn named(mut self, name: impl Into<String>) -> Container {
        self.name = Some(name.into());
        self
    }
    /// Relative sizes of the children (columns of a horizontal container, rows of a vertical one).
    pub fn shares(mut self, shares: impl Into<Vec<f32>>) -> Container {
        self.shares = Some(shares.into());
        self
    }
    fn path(&self) -> String {
        format!("container/{}", uuid_string(&self.id))
    }
}

impl View {
    fn new(class: &'static str, name: impl Into<String>, contents: impl IntoIterator<Item = String>) -> View {
        View {
            id: new_id(),
            class,
            name: name.into(),
            contents: contents.into_iter().collect(),
            properties: Vec::new(),
        }
    }
    pub fn spatial3d(name: impl Into<String>, contents: impl IntoIterator<Item = String>) -> View {
        View::new("3D", name, contents)
    }
    pub fn time_series(name: impl Into<String>, contents: impl IntoIterator<Item = String>) -> View {
        View::new("TimeSeries", name, contents)
    }
    pub fn bar_chart(name: impl Into<String>, contents: impl IntoIterator<Item = String>) -> View {
        View::new("BarChart", name, contents)
    }
    pub fn text_document(name: impl Into<String>, contents: impl IntoIterator<Item = String>) -> View {
        View::new("TextDocument", name, contents)
    }
    /// Sets a view property archetype, e.g. `("PlotLegend", &PlotLegend::new().with_visible(false))`.
    pub fn property(mut self, name: &'static str, archetype: &dyn AsComponents) -> View {
        self.properties.push((name, archetype.as_serialized_batches()));
        self
    }
    /// Hides the legend of a plot.
    pub fn without_legend(self) -> View {
        self.property("PlotLegend", &bp::PlotLegend::new().with_visible(false))
    }
    fn path(&self) -> String {
        format!("view/{}", uuid_string(&self.id))
    }
}

impl From<Container> for Node {
    fn from(c: Container) -> Node {
        Node::Container(c)
    }
}

impl From<View> for Node {
    fn from(v: View) -> Node {
        Node::View(v)
    }
}

impl Node {
    fn path(&self) -> String {
        match self {
            Node::Container(c) => c.path(),
            Node::View(v) => v.path(),
        }
    }

    fn log(&self, s: &RecordingStream) -> RecordingStreamResult<()> {
        match self {
            Node::View(v) => v.log(s),
            Node::Container(c) => c.log(s),
        }
    }
}

impl View {
    fn log(&self, s: &RecordingStream) -> RecordingStreamResult<()> {
        let path = self.path();
        let queries = self.contents.iter().map(|q| QueryExpression(q.as_str().into()));
        s.log(format!("{path}/ViewContents"), &bp::ViewContents::new(queries))?;
        s.log(
            path.as_str(),
            &bp::ViewBlueprint::new(ViewClass(self.class.into()))
                .with_display_name(Name(self.name.as_str().into()))
                .with_space_origin("/"),
        )?;
        for (name, batches) in &self.properties {
            s.log_serialized_batches(format!("{path}/{name}"), false, batches.iter().cloned())?;
        }
        Ok(())
    }
}

impl Container {
    fn log(&self, s: &RecordingStream) -> RecordingStreamResult<()> {
        for child in &self.children {
            child.log(s)?;
        }
        let mut a = bp::ContainerBlueprint::new(self.kind)
            .with_contents(self.children.iter().map(|ch| IncludedContent(ch.path().as_str().into())))
            .with_visible(Visible(true.into()));
        if let Some(n) = &self.name {
            a = a.with_display_name(Name(n.as_str().into()));
        }
        if let Some(sh) = &self.shares {
            a = match self.kind {
                ContainerKind::Vertical => a.with_row_shares(sh.iter().map(|&x| RowShare(x.into()))),
                _ => a.with_col_shares(sh.iter().map(|&x| ColumnShare(x.into()))),
            };
        }
        if let Some(g) = self.grid_columns {
            a = a.with_grid_columns(GridColumns(g.into()));
        }
        s.log(self.path(), &a)
    }
}

/// A whole layout: the root container, the selected timeline, and panel states. The time
/// cursor follows the latest data (live campaigns scroll; recordings open at their end).
pub struct Layout {
    pub root: Container,
    pub timeline: String,
    /// Blueprint (entity tree) and selection panels; collapsed leaves the views the screen.
    pub side_panels: PanelState,
    pub time_panel: PanelState,
}

impl Layout {
    /// Sends the layout to `rec` and makes it the active and default blueprint.
    pub fn send(&self, rec: &RecordingStream, app_id: &'static str) -> anyhow::Result<()> {
        let (s, storage) = crate::rerun::RecordingStreamBuilder::new(app_id).blueprint().memory()?;
        s.set_time_sequence("blueprint", 0);
        self.root.log(&s)?;
        s.log(
            "viewport",
            &bp::ViewportBlueprint::new()
                .with_root_container(RootContainer(self.root.id.into()))
                .with_auto_layout(AutoLayout(false.into()))
                .with_auto_views(AutoViews(false.into())),
        )?;
        s.log("blueprint_panel", &bp::PanelBlueprint::new().with_state(self.side_panels))?;
        s.log("selection_panel", &bp::PanelBlueprint::new().with_state(self.side_panels))?;
        s.log(
            "time_panel",
            &bp::TimePanelBlueprint::new()
                .with_state(self.time_panel)
                .with_timeline(TimelineName(self.timeline.as_str().into()))
                .with_play_state(PlayState::Following),
        )?;
        s.flush_blocking()?;
        let msgs: Vec<LogMsg> = storage.take();
        let Some(blueprint_id) = msgs.iter().find_map(|m| match m {
            LogMsg::SetStoreInfo(i) => Some(i.info.store_id.clone()),
            _ => None,
        }) else {
            return Ok(());
        };
        rec.send_blueprint(msgs, BlueprintActivationCommand { blueprint_id, make_active: true, make_default: true });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_sent_as_an_active_blueprint_with_its_views_and_properties() {
        let layout = Layout {
            root: Container::horizontal([
                View::time_series("a", ["+ /a/**".to_string()]).without_legend().into(),
                Container::grid(2, [View::bar_chart("b", ["+ /b/**".to_string()]).into()]).into(),
            ]),
            timeline: "position_mm".into(),
            side_panels: PanelState::Collapsed,
            time_panel: PanelState::Collapsed,
        };
        let (rec, storage) = crate::rerun::RecordingStreamBuilder::new("volcal").memory().unwrap();
        layout.send(&rec, "volcal").unwrap();
        rec.flush_blocking().unwrap();
        let msgs = storage.take();
        let activation = msgs.iter().find_map(|m| match m {
            LogMsg::BlueprintActivationCommand(c) => Some(c.clone()),
            _ => None,
        });
        let activation = activation.expect("no activation command");
        assert!(activation.make_active && activation.make_default);
        let entities: Vec<String> = msgs
            .iter()
            .filter_map(|m| match m {
                LogMsg::ArrowMsg(id, a) if *id == activation.blueprint_id => {
                    crate::rerun::log::Chunk::from_arrow_msg(a).ok().map(|c| c.entity_path().to_string())
                }
                _ => None,
            })
            .collect();
        let views = entities.iter().filter(|p| p.starts_with("/view/") && p.matches('/').count() == 2).count();
        let containers = entities.iter().filter(|p| p.starts_with("/container/")).count();
        assert_eq!((views, containers), (2, 2), "{entities:?}");
        assert!(entities.iter().any(|p| p.ends_with("/PlotLegend")), "{entities:?}");
        assert!(entities.iter().any(|p| p == "/viewport") && entities.iter().any(|p| p == "/time_panel"));
    }
}
