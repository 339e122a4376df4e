//! Mesh files: PLY (ascii, binary), OBJ and STL (ascii, binary) in; PLY out.
