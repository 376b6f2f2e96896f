% Load a model exported by ambid and print its frequency response G(e^{j2*pi*f*Ts}).
% MATLAB or Octave (Octave has no idpoly: the exported script then defines the plain vectors).
% Set model_file (the exported .m script; the .mat beside it is read too) and f_hz first:
%   model_file = 'models/oe8.m'; f_hz = [10, 100, 1000]; run('load_model.m')
run(model_file);                             % defines A, B, C, D, (F, K,) Ts, ...
s = load([model_file(1:end-2), '.mat']);      % the same numbers, with the text fields
q_inv = exp(-2i * pi * f_hz(:) * Ts);         % q^-1 on the unit circle
if strcmp(s.structure, 'ss')                  % G(z) = C (z I - A)^-1 B + D
  G = zeros(size(q_inv));
  for k = 1:numel(q_inv)
    G(k) = C * ((eye(size(A)) / q_inv(k) - A) \ B) + D;
  end
  p = eig(A);
else                                          % G = B / (A F), ascending powers of q^-1
  G = polyval(fliplr(B), q_inv) ./ (polyval(fliplr(A), q_inv) .* polyval(fliplr(F), q_inv));
  p = roots(conv(A, F));
end
fprintf('model %s: structure %s, Ts = %.6g s\n', s.model_name, s.structure, Ts);
fprintf('unstable poles: %d\n', sum(abs(p) >= 1));
for k = 1:numel(q_inv)
  fprintf('G %.17g %.17g %.17g\n', f_hz(k), real(G(k)), imag(G(k)));
end
