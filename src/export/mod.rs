//! Exports: OBJ + MTL, binary glTF.
