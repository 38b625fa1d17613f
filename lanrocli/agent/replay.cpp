// A recorded sequence of ATen operations, replayed from C++ (lanrocli/agent/replay.py records it).
//
// An update at batch 64 is a few hundred small operations, and on CPU each costs more to reach from Python,
// through autograd, than to compute. Replaying the operations that one update ran, forward and backward,
// as a list of dispatcher calls runs the same kernels on the same arguments in the same order, so it gives
// the same numbers bit for bit, without the interpreter or autograd between them.

#include <ATen/core/dispatch/Dispatcher.h>
#include <torch/csrc/jit/python/pybind_utils.h>
#include <torch/extension.h>

#include <string>
#include <utility>
#include <vector>

namespace py = pybind11;

namespace {

// One argument of a call: a value an earlier call made (or an input), a list of such values, or a constant.
struct Argument {
  enum class Kind { Value, Values, Constant } kind;
  int64_t slot = -1;
  std::vector<int64_t> slots;  // -1 for an optional tensor left out
  bool optional = false;       // the list is of optional tensors (Tensor?[])
  c10::IValue constant;
};

struct Call {
  c10::OperatorHandle op;
  std::vector<Argument> arguments;
  std::vector<int64_t> results;  // where each value the operator returns is kept
  bool unpack = false;           // the operator returns one list of tensors, whose elements go to `results`
  std::vector<int64_t> freed;  // values no later call reads, dropped after this one
};

// A constant as the dispatcher takes it. A Python number where the schema asks for a tensor becomes what
// torch's argument parser makes of it: a wrapped number, which type promotion treats as a scalar.
c10::IValue constant(const py::handle& value, const c10::TypePtr& type) {
  if (type->kind() == c10::TypeKind::TensorType && !THPVariable_Check(value.ptr())) {
    at::Tensor tensor = c10::scalar_to_tensor(torch::jit::toIValue(value, c10::NumberType::get()).toScalar());
    tensor.unsafeGetTensorImpl()->set_wrapped_number(true);
    return tensor;
  }
  return torch::jit::toIValue(value, type);
}

class Program {
 public:
  Program(int64_t slots, std::vector<int64_t> inputs, std::vector<int64_t> outputs)
      : slots_(slots), inputs_(std::move(inputs)), outputs_(std::move(outputs)) {
    for (const auto* slots_of : {&inputs_, &outputs_})
      for (const int64_t slot : *slots_of) TORCH_CHECK(slot >= 0 && slot < slots_, "slot ", slot, " out of range");
  }

  // `arguments`: per argument of the operator's schema, in order, a pair (kind, payload): ("value", slot),
  // ("values", [slots]) or ("constant", a Python value, converted by the argument's type in the schema).
  void add(const std::string& name, const std::string& overload, const py::list& arguments,
           std::vector<int64_t> results, bool unpack, std::vector<int64_t> freed) {
    const c10::OperatorHandle op = c10::Dispatcher::singleton().findSchemaOrThrow(name.c_str(), overload.c_str());
    const auto& schema = op.schema().arguments();
    TORCH_CHECK(arguments.size() == schema.size(), name, ".", overload, " takes ", schema.size(), " arguments, not ",
                arguments.size());
    Call call{op, {}, std::move(results), unpack, std::move(freed)};
    for (size_t i = 0; i < schema.size(); ++i) {
      const auto pair = arguments[i].cast<py::tuple>();
      const auto kind = pair[0].cast<std::string>();
      Argument argument;
      if (kind == "value") {
        argument.kind = Argument::Kind::Value;
        argument.slot = pair[1].cast<int64_t>();
      } else if (kind == "values") {
        argument.kind = Argument::Kind::Values;
        argument.slots = pair[1].cast<std::vector<int64_t>>();
        const auto list = schema[i].type()->cast<c10::ListType>();
        argument.optional = list && list->getElementType()->kind() == c10::TypeKind::OptionalType;
      } else {
        TORCH_CHECK(kind == "constant", "unknown argument kind ", kind);
        argument.kind = Argument::Kind::Constant;
        argument.constant = constant(pair[1], schema[i].type());
      }
      call.arguments.push_back(std::move(argument));
    }
    // A slot out of range would read or write past the values: checked once here, not at every replay.
    const auto check = [&](int64_t slot, bool may_be_absent) {
      TORCH_CHECK(slot < slots_ && (slot >= 0 || (may_be_absent && slot == -1)), name, ": slot ", slot, " out of range");
    };
    for (const Argument& argument : call.arguments) {
      if (argument.kind == Argument::Kind::Value) check(argument.slot, false);
      for (const int64_t slot : argument.slots) check(slot, argument.optional);
    }
    for (const int64_t slot : call.results) check(slot, true);
    for (const int64_t slot : call.freed) check(slot, false);
    calls_.push_back(std::move(call));
  }

  std::vector<at::Tensor> run(const std::vector<at::Tensor>& inputs) const {
    TORCH_CHECK(inputs.size() == inputs_.size(), "the program takes ", inputs_.size(), " inputs, not ", inputs.size());
    // The recorded operations are those autograd ran: replayed below it, they record no graph of their own.
    const at::AutoDispatchBelowADInplaceOrView below_autograd;
    std::vector<c10::IValue> values(slots_);
    for (size_t i = 0; i < inputs.size(); ++i) values[inputs_[i]] = inputs[i];
    torch::jit::Stack stack;
    for (const Call& call : calls_) {
      stack.clear();
      for (const Argument& argument : call.arguments) {
        switch (argument.kind) {
          case Argument::Kind::Value:
            stack.push_back(values[argument.slot]);
            break;
          case Argument::Kind::Values:
            if (argument.optional) {
              c10::List<std::optional<at::Tensor>> list;
              for (const int64_t slot : argument.slots)
                list.push_back(slot < 0 ? std::nullopt : std::optional<at::Tensor>(values[slot].toTensor()));
              stack.emplace_back(std::move(list));
            } else {
              c10::List<at::Tensor> list;
              list.reserve(argument.slots.size());
              for (const int64_t slot : argument.slots) list.push_back(values[slot].toTensor());
              stack.emplace_back(std::move(list));
            }
            break;
          case Argument::Kind::Constant:
            stack.push_back(argument.constant);
            break;
        }
      }
      call.op.callBoxed(stack);
      TORCH_CHECK(call.unpack || stack.size() >= call.results.size(), call.op.schema().name(), " returned ",
                  stack.size(), " values, not ", call.results.size());
      if (call.unpack) {
        const c10::List<at::Tensor> list = stack[0].toTensorList();
        for (size_t k = 0; k < call.results.size(); ++k)
          if (call.results[k] >= 0) values[call.results[k]] = list.get(k);
      } else {
        for (size_t k = 0; k < call.results.size(); ++k)
          if (call.results[k] >= 0) values[call.results[k]] = std::move(stack[k]);
      }
      for (const int64_t slot : call.freed) values[slot] = c10::IValue();
    }
    std::vector<at::Tensor> outputs;
    outputs.reserve(outputs_.size());
    for (const int64_t slot : outputs_) outputs.push_back(values[slot].toTensor());
    return outputs;
  }

 private:
  int64_t slots_;
  std::vector<int64_t> inputs_, outputs_;
  std::vector<Call> calls_;
};

}  // namespace

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  py::class_<Program>(m, "Program")
      .def(py::init<int64_t, std::vector<int64_t>, std::vector<int64_t>>())
      .def("add", &Program::add)
      .def("run", &Program::run, py::call_guard<py::gil_scoped_release>());
}
