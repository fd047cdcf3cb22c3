"""d-model execution: reference interpreter, C code generator, FMU builder, verifier."""
