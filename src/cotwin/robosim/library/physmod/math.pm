// cotwin's built-in physmod math library (RoboTool's physmod::math): functions usable in equations
// and mappings. Equations of p-models are relations for a solver; cotwin checks their names, it
// does not solve them.
package physmod::math

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

// spatial algebra used by the joint libraries (6-vectors are [angular; linear])
function transpose(m: matrix(real, 6, 6)): matrix(real, 6, 6) { }
function identity(n: nat): matrix(real, 6, 6) { }
function skew(v: vector(real, 3)): matrix(real, 3, 3) { }
function Xrot(axis: vector(real, 3), angle: real): matrix(real, 6, 6) { }
function Xtrans(r: vector(real, 3)): matrix(real, 6, 6) { }
