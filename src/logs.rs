//! Log readers and writers: CARMEN, TUM.
