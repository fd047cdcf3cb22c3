// RoboChart's sequence toolkit. cotwin's models use no sequence function yet; the package exists so
// that `import sequence_toolkit::*` resolves.
