//! Dataset formats: BOP and ROBI.
