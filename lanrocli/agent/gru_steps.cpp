// The word-by-word loops of lanrocli/agent/gru.py (forward_steps, backward_steps) in C++, for CPU tensors.
//
// The Python loops make about fifteen small tensor operations a word forward and eight backward, and on a
// batch of a few dozen short sentences each costs more in dispatch and allocation than in arithmetic. Here
// a step's element-wise work is plain loops, and ATen is called only for what is not plain IEEE arithmetic:
// the matrix products and the sigmoids, on tensors of the shapes and layouts the Python gives them. The
// loops apply each addition, subtraction and multiplication in the Python's order, with its roundings:
// compiled with -ffp-contract=off so that none is fused, but for the two that ATen's addcmul fuses on CPU
// (std::fma here). So the results are the Python loops' bit for bit; tests/agent/test_native.py holds them
// to it, on the machine that runs the tests.

#include <ATen/ATen.h>
#include <torch/library.h>

#include <cmath>
#include <vector>

namespace {

// Rows [from, to) of a [members, rows, width] contiguous tensor copied to the same rows of another.
void copy_rows(const at::Tensor& source, const at::Tensor& target, int64_t from, int64_t to) {
  target.slice(1, from, to).copy_(source.slice(1, from, to));
}

template <typename T>
std::vector<at::Tensor> forward_typed(const at::Tensor& inputs_any, const at::Tensor& weight_hh,
                                      const at::Tensor& bias_hh, at::IntArrayRef active, int64_t trained, bool keep) {
  const at::Tensor inputs = inputs_any.contiguous();
  const int64_t members = inputs.size(0), packed = inputs.size(1), gates = inputs.size(2), size = gates / 3;
  const int64_t rows = active[0];
  const at::Tensor weight_t = weight_hh.transpose(1, 2), bias = bias_hh.unsqueeze(1);
  const auto options = inputs.options();
  at::Tensor last = at::empty({members, rows, size}, options);
  at::Tensor h = at::zeros({members, rows, size}, options);
  // What the backward pass needs of the first `trained` members, packed as the inputs are.
  at::Tensor before, rz_kept, n_kept, hidden_n_kept;
  if (keep) {
    before = at::empty({trained, packed, size}, options);
    rz_kept = at::empty({trained, packed, 2 * size}, options);
    n_kept = at::empty({trained, packed, size}, options);
    hidden_n_kept = at::empty({trained, packed, size}, options);
  }
  const T* x_all = inputs.data_ptr<T>();
  int64_t start = 0, width = rows;  // width: the rows of h, those that read a word at the step before
  for (const int64_t k : active) {
    if (k < width) copy_rows(h, last, k, width);  // those sentences have ended: their state is final
    const at::Tensor h_read = k < width ? h.slice(1, 0, k) : h;
    const at::Tensor hidden = at::baddbmm(bias, h_read, weight_t).contiguous();  // [members, k, 3 * size]
    at::Tensor rz_in = at::empty({members, k, 2 * size}, options);
    const T* hid = hidden.data_ptr<T>();
    T* __restrict__ rz_in_p = rz_in.data_ptr<T>();
    for (int64_t m = 0; m < members; ++m) {
      for (int64_t i = 0; i < k; ++i) {
        const T* x = x_all + (m * packed + start + i) * gates;
        const T* hd = hid + (m * k + i) * gates;
        for (int64_t j = 0; j < 2 * size; ++j) rz_in_p[(m * k + i) * 2 * size + j] = x[j] + hd[j];
      }
    }
    const at::Tensor rz = at::sigmoid(rz_in);
    const T* rz_p = rz.data_ptr<T>();
    at::Tensor n_in = at::empty({members, k, size}, options);  // 2 (x W_in + b_in + r * (h W_hn + b_hn))
    T* __restrict__ n_in_p = n_in.data_ptr<T>();
    for (int64_t m = 0; m < members; ++m) {
      for (int64_t i = 0; i < k; ++i) {
        const T* x = x_all + (m * packed + start + i) * gates + 2 * size;
        const T* hn = hid + (m * k + i) * gates + 2 * size;
        const T* r = rz_p + (m * k + i) * 2 * size;
        for (int64_t j = 0; j < size; ++j) n_in_p[(m * k + i) * size + j] = std::fma(r[j], hn[j], x[j]) * T(2);
      }
    }
    const at::Tensor sig = at::sigmoid(n_in);  // tanh(v) = 2 sigmoid(2v) - 1, as gru.py's _tanh
    const T* sig_p = sig.data_ptr<T>();
    const T* h_p = h.data_ptr<T>();
    at::Tensor h_next = at::empty({members, k, size}, options), n = at::empty({members, k, size}, options);
    T* __restrict__ next_p = h_next.data_ptr<T>();
    T* __restrict__ n_p = n.data_ptr<T>();
    for (int64_t m = 0; m < members; ++m) {
      for (int64_t i = 0; i < k; ++i) {
        const int64_t row = m * k + i;
        const T* h_row = h_p + (m * width + i) * size;
        const T* z = rz_p + row * 2 * size + size;
        for (int64_t j = 0; j < size; ++j) {
          const T value = sig_p[row * size + j] * T(2) - T(1);
          n_p[row * size + j] = value;
          next_p[row * size + j] = std::fma(z[j], h_row[j] - value, value);
        }
      }
    }
    if (keep) {
      before.slice(1, start, start + k).copy_(h_read.slice(0, 0, trained));
      rz_kept.slice(1, start, start + k).copy_(rz.slice(0, 0, trained));
      n_kept.slice(1, start, start + k).copy_(n.slice(0, 0, trained));
      hidden_n_kept.slice(1, start, start + k).copy_(hidden.slice(0, 0, trained).slice(2, 2 * size));
    }
    start += k;
    h = h_next;
    width = k;
  }
  copy_rows(h, last, 0, width);
  if (!keep) return {last};
  return {last, before, rz_kept, n_kept, hidden_n_kept};
}

template <typename T>
std::vector<at::Tensor> backward_typed(const at::Tensor& grad_any, const at::Tensor& weight_hh,
                                       const at::Tensor& before_any, const at::Tensor& rz_any,
                                       const at::Tensor& n_any, const at::Tensor& hidden_n_any,
                                       at::IntArrayRef active) {
  const int64_t members = weight_hh.size(0);
  const at::Tensor grad = grad_any.slice(0, 0, members).contiguous();
  const at::Tensor before = before_any.contiguous(), rz = rz_any.contiguous(), n_all = n_any.contiguous();
  const at::Tensor hidden_n = hidden_n_any.contiguous();
  const int64_t packed = before.size(1), size = before.size(2);
  const int64_t steps = static_cast<int64_t>(active.size());
  const auto options = before.options();
  // What does not depend on the incoming gradient, for all steps at once: the derivatives of h' with
  // respect to the recurrent gate inputs h W_h + b_h (r, z, n), and to n's pre-activation.
  at::Tensor to_n = at::empty({members, packed, size}, options);
  at::Tensor to_hidden = at::empty({members, packed, 3 * size}, options);
  {
    const T *b = before.data_ptr<T>(), *rz_p = rz.data_ptr<T>(), *n_p = n_all.data_ptr<T>();
    const T* hn = hidden_n.data_ptr<T>();
    T* __restrict__ to_n_p = to_n.data_ptr<T>();
    T* __restrict__ to_h = to_hidden.data_ptr<T>();
    for (int64_t row = 0; row < members * packed; ++row) {
      for (int64_t j = 0; j < size; ++j) {
        const T r = rz_p[row * 2 * size + j], z = rz_p[row * 2 * size + size + j], n = n_p[row * size + j];
        const T squared = n * n;
        const T t_n = (T(1) - z) * (T(1) - squared);
        const T a = t_n * hn[row * size + j];
        const T a_r = a * r;
        to_h[row * 3 * size + j] = a_r * (T(1) - r);
        const T gap = b[row * size + j] - n;
        const T gap_z = gap * z;
        to_h[row * 3 * size + size + j] = gap_z * (T(1) - z);
        to_h[row * 3 * size + 2 * size + j] = t_n * r;
        to_n_p[row * size + j] = t_n;
      }
    }
  }
  std::vector<int64_t> ends(steps);
  int64_t total = 0;
  for (int64_t t = 0; t < steps; ++t) ends[t] = (total += active[t]);
  at::Tensor hidden_all = at::empty({members, packed, 3 * size}, options);  // gradients of h W_h + b_h
  at::Tensor grad_inputs = at::empty({members, packed, 3 * size}, options);
  at::Tensor g = grad.slice(1, 0, active[steps - 1]).contiguous();  // the gradient of the state after step t
  const T *rz_p = rz.data_ptr<T>(), *to_h = to_hidden.data_ptr<T>();
  const T* to_n_p = to_n.data_ptr<T>();
  T* __restrict__ all_p = hidden_all.data_ptr<T>();
  T* __restrict__ in_p = grad_inputs.data_ptr<T>();
  for (int64_t t = steps - 1; t >= 0; --t) {
    const int64_t k = active[t], from = ends[t] - k;
    at::Tensor step = at::empty({members, k, 3 * size}, options);
    at::Tensor g_z = at::empty({members, k, size}, options);
    const T* g_p = g.data_ptr<T>();
    T* __restrict__ step_p = step.data_ptr<T>();
    T* __restrict__ g_z_p = g_z.data_ptr<T>();
    for (int64_t m = 0; m < members; ++m) {
      for (int64_t i = 0; i < k; ++i) {
        const int64_t row = m * packed + from + i;
        const T* gr = g_p + (m * k + i) * size;
        for (int64_t q = 0; q < 3; ++q) {
          for (int64_t j = 0; j < size; ++j) {
            const T value = to_h[row * 3 * size + q * size + j] * gr[j];
            step_p[(m * k + i) * 3 * size + q * size + j] = value;
            all_p[row * 3 * size + q * size + j] = value;
          }
        }
        for (int64_t j = 0; j < 2 * size; ++j) in_p[row * 3 * size + j] = all_p[row * 3 * size + j];
        for (int64_t j = 0; j < size; ++j) {
          g_z_p[(m * k + i) * size + j] = gr[j] * rz_p[row * 2 * size + size + j];
          in_p[row * 3 * size + 2 * size + j] = gr[j] * to_n_p[row * size + j];
        }
      }
    }
    g = at::baddbmm(g_z, step, weight_hh);  // with respect to h before the step
    if (t > 0 && active[t - 1] > k) {  // rows whose sentence ended at step t - 1 join
      at::Tensor joined = at::empty({members, active[t - 1], size}, options);
      joined.slice(1, 0, k).copy_(g);
      joined.slice(1, k).copy_(grad.slice(1, k, active[t - 1]));
      g = joined;
    }
  }
  return {grad_inputs, at::bmm(hidden_all.transpose(1, 2), before), hidden_all.sum(1)};
}

std::vector<at::Tensor> forward(const at::Tensor& inputs, const at::Tensor& weight_hh, const at::Tensor& bias_hh,
                                at::IntArrayRef active, int64_t trained, bool keep) {
  TORCH_CHECK(inputs.is_cpu(), "lanro_gru.forward runs on CPU tensors");
  std::vector<at::Tensor> out;
  AT_DISPATCH_FLOATING_TYPES(inputs.scalar_type(), "lanro_gru.forward", [&] {
    out = forward_typed<scalar_t>(inputs, weight_hh, bias_hh, active, trained, keep);
  });
  return out;
}

std::vector<at::Tensor> backward(const at::Tensor& grad, const at::Tensor& weight_hh, const at::Tensor& before,
                                 const at::Tensor& rz, const at::Tensor& n, const at::Tensor& hidden_n,
                                 at::IntArrayRef active) {
  TORCH_CHECK(grad.is_cpu(), "lanro_gru.backward runs on CPU tensors");
  std::vector<at::Tensor> out;
  AT_DISPATCH_FLOATING_TYPES(grad.scalar_type(), "lanro_gru.backward", [&] {
    out = backward_typed<scalar_t>(grad, weight_hh, before, rz, n, hidden_n, active);
  });
  return out;
}

}  // namespace

// The namespace is native.py's LIBRARY.
TORCH_LIBRARY(lanro_gru, m) {
  m.def("forward(Tensor inputs, Tensor weight_hh, Tensor bias_hh, int[] active, int trained, bool keep) -> Tensor[]",
        &forward);
  m.def(
      "backward(Tensor grad, Tensor weight_hh, Tensor before, Tensor rz, Tensor n, Tensor hidden_n, int[] active) "
      "-> Tensor[]",
      &backward);
}
