//! The table under a DFS scene ([`DfsParams::table_height`](super::DfsParams::table_height)):
//! its support wrench on an object in the object stage, and lifting an object the step left in
//! it out (the module documentation of [`dfs`](super) and [`crate::table`]).

use super::Dfs;
use crate::math::Wrench;
use crate::table::Table;

impl Dfs {
    /// The table, if the scene has one.
    fn table(&self) -> Option<Table> {
        self.params.table_height.map(|height| Table {
            height,
            mu: self.params.table_mu,
            rolling: self.params.table_rolling,
        })
    }

    /// The table's wrench on object `i` (B) given every other force `f_b` on it this tick:
    /// support at its lowest points with friction ([`Table::support_wrench_b`]).
    pub(super) fn table_wrench_b(&mut self, i: usize, f_b: &Wrench) -> Wrench {
        let Some(table) = self.table() else {
            return Wrench::zeros();
        };
        let (o, support) = (&self.objects[i], &mut self.table_support[i]);
        table.support_wrench_b(support, &o.object, &o.state, f_b, self.params.dt)
    }

    /// Lifts object `i` out of the table if the step left it below ([`Table::lift_out`]).
    pub(super) fn clamp_to_table(&mut self, i: usize) {
        if let Some(table) = self.table() {
            let o = &mut self.objects[i];
            table.lift_out(&o.object.shape, &mut o.state);
        }
    }
}
