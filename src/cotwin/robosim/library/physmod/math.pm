// cotwin's built-in physmod math library: functions usable in equations and mappings.
function derivative(x: real): real { }
function integral(x: real, from: real, to: real): real { }
function sqrt(x: real): real { }
function sin(x: real): real { }
function cos(x: real): real { }
function tan(x: real): real { }
function asin(x: real): real { }
function acos(x: real): real { }
function atan(x: real): real { }
function atan2(y: real, x: real): real { }
function exp(x: real): real { }
function log(x: real): real { }
function abs(x: real): real { }
function min(a: real, b: real): real { }
function max(a: real, b: real): real { }
function pow(x: real, y: real): real { }
