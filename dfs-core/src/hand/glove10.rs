//! The built-in `glove10` model of the paper's sensor glove (§2.2, Fig. 3).

use super::HandModel;

impl HandModel {
    /// The paper's 10-DOF glove: wrist 3, index 3, thumb 2, middle/ring/little 2 coupled.
    pub fn glove10() -> HandModel {
        todo!("glove10")
    }
}
