"""Real hardware drivers (serial turntables, serial projectors, depthai cameras). See issue 5."""
